//! Conversion of one frame to a `.mdlod` file: species looks, hierarchy, metadata, write.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use mdlod_format::meta::{AttributeInfo, BuildInfo, Metadata, SourceInfo};
use mdlod_format::FormatError;

use crate::chunked::{convert_chunked, ChunkOptions, DumpSource, FrameSource};
use crate::frame::{Frame, SpeciesName};
use crate::hierarchy::{self, BuildError, BuildParams, Particles};
use crate::progress::Progress;
use crate::species::species_table;

/// How to convert.
#[derive(Clone, Debug, Default)]
pub struct ConvertOptions {
    pub build: BuildParams,
    /// Radius overrides by species name.
    pub radii: Vec<(String, f32)>,
    /// When and how frames are built in chunks (out of core).
    pub chunks: ChunkOptions,
    /// Whether an override may name a species the frame does not hold: true for the
    /// frames of a trajectory, where a species may appear in some frames only; false
    /// (the default) makes it an error listing the frame's species (a misspelt name).
    pub radii_may_be_absent: bool,
    /// Species renamed (`--species-name 1=O`), input name to the file's, applied before
    /// the radii and looks are chosen (so `radii` name species by their new names); two
    /// species given one name become one. A name the input lacks is an error unless
    /// `radii_may_be_absent`.
    pub species_names: Vec<(String, String)>,
    /// Store the attribute's base-10 logarithm (named `log10(NAME)`), so that 16 bits
    /// keep every decade of a quantity spanning many (SPH densities): values must be
    /// above 0 ([`log10_attribute`]).
    pub attribute_log10: bool,
    /// For each further attribute in turn (`convert_frame_with`'s `further`, a reader's
    /// `extra_attributes`), whether the file keeps its base-10 logarithm
    /// (`AttributeInfo::log10`, named `log10(NAME)`), as `attribute_log10` for the first:
    /// its values must then be above 0. Missing entries are `false`; one set beyond the
    /// further attributes is an error.
    pub extra_log10: Vec<bool>,
    /// The input column whose values are the species (`ReadOptions::species_column`),
    /// recorded in the metadata: [`convert_dump`] and batches fill it in from their read
    /// options; a caller of [`convert_frame`] sets it for a frame so read.
    pub species_column: Option<String>,
    /// The options that changed what was read from the input, as the command line gave
    /// them (`--wrap`, `--no-sizes`, `--species-name W=SOL`, ...), recorded in the
    /// metadata (`input_options`): the file's data is its input's only with them.
    pub input_options: Vec<String>,
}

/// What a conversion built.
#[derive(Clone, Debug)]
pub struct ConvertReport {
    pub particles: u64,
    pub levels: usize,
    pub nodes: usize,
    pub max_position_error: f64,
    /// Time spent opening (indexing), reading and parsing the input (zero for
    /// [`convert_frame`]).
    pub read_time: Duration,
    pub build_time: Duration,
    pub write_time: Duration,
    pub file_size: u64,
    /// What the user should know about the conversion (see
    /// [`crate::convert::position_notes`]).
    pub notes: Vec<String>,
    /// The frame converted and how many frames the input has (set by
    /// [`convert_dump`] and [`convert_file`]; `None` for a frame given in memory).
    pub frame: Option<(usize, usize)>,
}

#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error(transparent)]
    Read(#[from] crate::readers::ReadError),
    /// Extra attributes a conversion cannot keep ([`convert_frame_with`]).
    #[error("{place}: {problem}")]
    Attributes { place: FramePlace, problem: String },
    /// `--attribute-log10` and an attribute value that has no logarithm.
    #[error(
        "{place}: attribute {name}: particle {index} (counting from 0, in the input's order) \
         has the value {value}: its logarithm (--attribute-log10) needs values above 0"
    )]
    AttributeNotPositive {
        place: FramePlace,
        name: String,
        index: usize,
        value: f32,
    },
    /// A simulation box that is not finite (bounds whose extent overflows, a NaN).
    #[error("{place}: the simulation box is not finite ({problem}); the input's box bounds cannot be kept")]
    BadBox { place: FramePlace, problem: String },
    /// `--attribute-log10` for an input that keeps no attribute.
    #[error(
        "{0}: --attribute-log10: the input keeps no per-particle attribute to take the \
         logarithm of (name its column with --attribute COLUMN)"
    )]
    NoAttributeToLog(FramePlace),
    /// The last frame, converted by default, is cut short (a run still writing it).
    #[error(
        "{source}; the last frame ({frame}) is incomplete (a run still writing?): --frame {} \
         converts the last complete one",
        .frame - 1
    )]
    LastFrameIncomplete {
        frame: usize,
        #[source]
        source: crate::readers::ReadError,
    },
    /// The last frame, asked for by default, holds no particles (a discharge that
    /// empties the box, a pour that starts empty): which frame holds some.
    #[error(
        "{place}: no particles, and a .mdlod file needs at least one; {}",
        match with_particles {
            Some((j, Some(t))) => format!(
                "the last frame with particles is frame {j} (timestep {t}): --frame {j} \
                 converts it"
            ),
            Some((j, None)) => {
                format!("the last frame with particles is frame {j}: --frame {j} converts it")
            }
            None => "no frame of the input holds particles".to_string(),
        }
    )]
    LastFrameEmpty {
        place: FramePlace,
        /// The last frame (index, timestep) that holds particles, if any does.
        with_particles: Option<(usize, Option<u64>)>,
    },
    #[error("{path}: {source}")]
    Build {
        path: String,
        #[source]
        source: BuildError,
    },
    #[error(transparent)]
    Write(#[from] FormatError),
    #[error("working file {path}: {source}")]
    Temp {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Boxed: the message's file and naming would make every conversion result large.
    #[error(transparent)]
    Species(#[from] Box<crate::species::UnknownSpecies>),
    /// Boxed, as [`ConvertError::Species`].
    #[error(transparent)]
    UnknownRename(#[from] Box<crate::species::UnknownRename>),
    #[error("chunked conversion: {0}")]
    Chunked(String),
    /// A frame built in memory (within the chunk size) that needs more than the limit.
    #[error("{place}: {particles} particles are built in memory (within --chunk-points {chunk_points}) and need about {}, above the memory limit of {}: raise --memory-limit{}", crate::chunked::need_text(*need), crate::chunked::size_text(*limit), chunk_hint(*particles, *limit, *root_points, *extras))]
    MemoryLimit {
        place: FramePlace,
        particles: usize,
        chunk_points: usize,
        need: u64,
        limit: u64,
        /// The root points of the build: chunks hold at least as many.
        root_points: u32,
        /// Further attributes kept beside the first.
        extras: usize,
    },
    /// A frame without particles: a `.mdlod` file needs at least one.
    #[error("{0}: no particles, and a .mdlod file needs at least one")]
    EmptyFrame(FramePlace),
    /// Boxed: a species whose radius from the input cannot be drawn.
    #[error(transparent)]
    UnusableRadius(Box<UnusableRadius>),
    /// An error in the text a large gzip input was decompressed into (the place is a
    /// line of that text, said as the input's: the working file is gone by the time the
    /// message is read).
    /// A frame cut short, or past the end, of a gzip input whose compressed stream ends
    /// early: the cut is named with it (the frames before it convert).
    #[error(
        "{source}; {}'s compressed stream ends early (a run still writing it, or a copy cut \
         short): the frames before the cut convert",
        input.display()
    )]
    GzipCut {
        input: std::path::PathBuf,
        #[source]
        source: Box<ConvertError>,
    },
    /// (Not the error's source: the message says it, the working file's path put as the
    /// input's line, and a source would print that path again.)
    #[error("{}", decompressed_message(input, text, inner))]
    Decompressed {
        input: std::path::PathBuf,
        text: std::path::PathBuf,
        inner: Box<ConvertError>,
    },
}

/// The memory a frame of `particles` needs to be read and built in memory.
pub fn in_memory_need(particles: usize) -> u64 {
    (particles as u64).saturating_mul(crate::batch::BYTES_PER_PARTICLE)
}

/// Refuses to build a frame of `particles` in memory, with `extras` further attributes,
/// when that needs more than the limit.
pub(crate) fn check_in_memory(
    particles: usize,
    extras: usize,
    options: &ConvertOptions,
    place: impl FnOnce() -> FramePlace,
) -> Result<(), ConvertError> {
    // Each further attribute adds what it adds to a chunk's build.
    let per_extra =
        crate::chunked::build_bytes_per_particle(extras) - crate::chunked::BUILD_BYTES_PER_PARTICLE;
    let need =
        in_memory_need(particles).saturating_add((particles as u64).saturating_mul(per_extra));
    let limit = options.chunks.memory_limit;
    if need <= limit {
        return Ok(());
    }
    Err(ConvertError::MemoryLimit {
        place: place(),
        particles,
        chunk_points: options.chunks.chunk_points,
        need,
        limit,
        root_points: options.build.max_root_points,
        extras,
    })
}

/// How to build a frame of `particles` (with `extras` further attributes) out of core
/// within `limit`, if chunks of at least the build's `root_points` fit in it.
fn chunk_hint(particles: usize, limit: u64, root_points: u32, extras: usize) -> String {
    match crate::chunked::chunk_points_within(limit, root_points, extras) {
        Some(points) if points < particles as u64 => {
            format!(", or build it out of core in smaller chunks (--chunk-points {points})")
        }
        _ => String::new(),
    }
}

/// Which frame of which input: `path: frame K (timestep T)`, as far as known.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePlace {
    /// The input (`input` when unknown).
    pub path: String,
    /// The frame's index in the input.
    pub frame: Option<u64>,
    pub timestep: Option<u64>,
}

impl FramePlace {
    /// The place of a frame converted from `source` (if known) with `timestep`.
    pub fn of(source: Option<&SourceInfo>, timestep: Option<u64>) -> FramePlace {
        FramePlace {
            path: source.map_or_else(|| "input".to_string(), |s| s.path.clone()),
            frame: source.map(|s| s.frame),
            timestep,
        }
    }
}

impl std::fmt::Display for FramePlace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.path)?;
        match (self.frame, self.timestep) {
            (Some(k), Some(t)) => write!(f, ": frame {k} (timestep {t})"),
            (Some(k), None) => write!(f, ": frame {k}"),
            (None, Some(t)) => write!(f, ": timestep {t}"),
            (None, None) => Ok(()),
        }
    }
}

/// A species whose radius from the input is zero, below or not a number, with no
/// `--radius` for it: refused rather than drawn with a made-up size.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct UnusableRadius {
    pub place: FramePlace,
    pub species: String,
    /// The radius the input gives.
    pub radius: f32,
    /// The input's format, where known: it says what the species is (an MMPLD list, a
    /// GSD type) and where its size comes from.
    pub format: Option<crate::readers::InputFormat>,
    /// The first particle (its index in the frame's order) whose own size is unusable,
    /// where the frame gives particles their own sizes.
    pub particle: Option<usize>,
}

impl std::fmt::Display for UnusableRadius {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use crate::readers::InputFormat;
        let (place, name, r) = (&self.place, &self.species, self.radius);
        let (what, size) = match self.format {
            Some(InputFormat::Mmpld) => ("list", format!("radius {r}")),
            Some(InputFormat::Gsd) => (
                "type",
                format!("a particle diameter of {}", 2.0 * f64::from(r)),
            ),
            // (A dump's size column of 0: the species' range starts there.)
            _ if r == 0.0 => ("species", "a particle of size 0".to_string()),
            _ => ("species", format!("radius {r}")),
        };
        let size = match self.particle {
            Some(i) => {
                format!("{size} (particle {i} in the frame's order, counting from 0, is the first)")
            }
            None => size,
        };
        let sep = if place.frame.is_some() || place.timestep.is_some() {
            ", "
        } else {
            ": "
        };
        // A size column of 0 for some particles: --radius replaces every particle's own
        // size, which a file whose other sizes matter (smoothing lengths) must not lose.
        let own = if (r == 0.0
            && !matches!(self.format, Some(InputFormat::Mmpld | InputFormat::Gsd)))
            || self.particle.is_some()
        {
            if r == 0.0 {
                " (every particle of it then takes R, those of sizes above 0 too: where \
                 their sizes matter, mend the sizes of 0 in the input instead)"
            } else {
                " (every particle of it then takes R, those of usable sizes too: where \
                 their sizes matter, mend the unusable ones in the input instead)"
            }
        } else {
            ""
        };
        write!(
            f,
            "{place}{sep}{what} {name}: the file gives {size}, and a radius must be a positive \
             number; give the {what} its radius with --radius {name}=R{own}"
        )
    }
}

impl From<crate::species::UnknownSpecies> for ConvertError {
    fn from(e: crate::species::UnknownSpecies) -> Self {
        ConvertError::Species(Box::new(e))
    }
}

/// Builds the hierarchy of `frame` and writes it to `output`. `source` describes where
/// the frame came from (recorded in the metadata).
pub fn convert_frame(
    frame: &Frame,
    source: Option<SourceInfo>,
    output: &Path,
    options: &ConvertOptions,
    progress: &dyn Progress,
) -> Result<ConvertReport, ConvertError> {
    convert_frame_with(frame, &[], source, output, options, progress)
}

/// [`convert_frame`], keeping `further` attributes too: per-particle columns beside the
/// frame's attribute (format 1.2's ATTRIBUTES, [`hierarchy::extra`]), each one value
/// per particle in the frame's order. They need the frame's attribute (the first).
pub fn convert_frame_with(
    frame: &Frame,
    further: &[crate::frame::Attribute],
    source: Option<SourceInfo>,
    output: &Path,
    options: &ConvertOptions,
    progress: &dyn Progress,
) -> Result<ConvertReport, ConvertError> {
    if !further.is_empty() || !options.extra_log10.is_empty() {
        check_extras(frame, further, source.as_ref(), options)?;
    }
    if frame.is_empty() {
        return Err(ConvertError::EmptyFrame(FramePlace::of(
            source.as_ref(),
            frame.timestep,
        )));
    }
    check_box(frame.simulation_box.as_ref(), || {
        FramePlace::of(source.as_ref(), frame.timestep)
    })?;
    if !options.radii_may_be_absent {
        crate::species::check_renames(&frame.species, &options.species_names)?;
    }
    // (Particles per species, for the means of species a rename merges.)
    let counts = match options.species_names.is_empty() {
        true => Vec::new(),
        false => crate::species::counts(frame.species.len(), &frame.species_index),
    };
    let (names, merged) =
        crate::species::rename_species(&frame.species, &counts, &options.species_names);
    if !options.radii_may_be_absent {
        crate::species::check_overrides(&names, &options.radii)?;
    }
    check_radii(&names, options, source.as_ref(), frame.timestep)
        .map_err(|e| with_particle(e, frame, options))?;
    if frame.len() > options.chunks.chunk_points {
        // (Its notes, those of the radii included, are the chunked build's.)
        let metadata = base_metadata(frame, source, options);
        return convert_chunked(
            &FrameSource(frame, further),
            metadata,
            output,
            options,
            progress,
        );
    }
    let override_notes = radius_notes(&names, &options.radii);
    check_in_memory(frame.len(), further.len(), options, || {
        FramePlace::of(source.as_ref(), frame.timestep)
    })?;
    let species = species_table(&names, &options.radii);
    // Species merged by their new names: the particles' indices into the new list.
    let merged_index: Option<Vec<u16>> = merged.map(|map| {
        frame
            .species_index
            .iter()
            .map(|&i| map.get(usize::from(i)).copied().unwrap_or(i))
            .collect()
    });
    // The range of the logarithm stored, where one is.
    let logged = match (&frame.attribute, options.attribute_log10) {
        (Some(a), true) => Some(log10_range(&a.values, 0, &a.name, source.as_ref())?),
        (None, true) => {
            return Err(ConvertError::NoAttributeToLog(FramePlace::of(
                source.as_ref(),
                frame.timestep,
            )))
        }
        _ => None,
    };
    // Further columns kept as logarithms: above 0, said naming the particle before the
    // build.
    for (_, e) in further
        .iter()
        .enumerate()
        .filter(|(k, _)| options.extra_logged(*k))
    {
        log10_range(&e.values, 0, &e.name, source.as_ref())?;
    }
    let species_index = merged_index.as_deref().unwrap_or(&frame.species_index);
    let radii = hierarchy::particle_radii(&species, species_index, frame.radii.as_deref());
    // (A logarithm is stored from the values themselves, which clusters average: see
    // `BuildExtras::attribute_log10`.)
    let particles = Particles {
        positions: &frame.positions,
        species_index,
        species: &species,
        attribute: frame.attribute.as_ref().map(|a| a.values.as_slice()),
        radii: radii.as_deref(),
    };
    let t0 = Instant::now();
    let source_name = source
        .as_ref()
        .map_or_else(|| "input".to_string(), |s| s.path.clone());
    // The radii's range from the species with particles, as a chunked build takes it.
    let extras = hierarchy::BuildExtras {
        radius_range: radii.as_ref().and_then(|_| {
            hierarchy::radius_range(
                &species,
                &crate::species::counts(species.len(), species_index),
            )
        }),
        attribute_log10: logged.is_some(),
        attribute_range: logged,
        ..Default::default()
    };
    let h = hierarchy::build_with(particles, &options.build, &extras, progress).map_err(|e| {
        ConvertError::Build {
            path: source_name,
            source: e,
        }
    })?;
    let mut h = h;
    let names: Vec<String> = further
        .iter()
        .enumerate()
        .map(|(k, e)| extra_attribute_name(&e.name, k, options))
        .collect();
    let columns: Vec<hierarchy::extra::ExtraColumn> = further
        .iter()
        .zip(&names)
        .enumerate()
        .map(|(k, (e, name))| hierarchy::extra::ExtraColumn {
            name,
            values: &e.values,
            log10: options.extra_logged(k),
        })
        .collect();
    h.extra_attributes =
        hierarchy::extra::extra_attributes(&h, &columns, &species).map_err(|err| {
            ConvertError::Build {
                path: source
                    .as_ref()
                    .map_or_else(|| "input".to_string(), |s| s.path.clone()),
                source: err,
            }
        })?;
    let build_time = t0.elapsed();
    let mut notes = override_notes;
    // The columns kept as logarithms, by their input names (a note's advice names them).
    let logged: Vec<String> = frame
        .attribute
        .iter()
        .filter(|_| options.attribute_log10)
        .map(|a| a.name.clone())
        .chain(
            further
                .iter()
                .enumerate()
                .filter(|(k, _)| options.extra_logged(*k))
                .map(|(_, e)| e.name.clone()),
        )
        .collect();
    if let (Some(a), Some((_, min, max))) = (&frame.attribute, &h.attribute) {
        // Ids (of molecules, clusters) are told by their whole numbers, which no
        // logarithm keeps apart either.
        let ids = (!options.attribute_log10)
            .then(|| whole_numbers_note(&a.name, &a.values, *min, *max))
            .flatten();
        if let Some(ids) = ids {
            notes.extend(ids);
        } else {
            let mut said = Vec::new();
            let octaves = std::cell::OnceCell::new();
            let octaves = || octaves.get_or_init(|| Octaves::of(&a.values)).clone();
            said.extend(attribute_span_note(
                &a.name, *min, *max, options, &logged, &octaves,
            ));
            if !options.attribute_log10 {
                // (A few far values stretching the range say so, rather than that the
                // values above 0 fall below a step, whose remedy is a logarithm's.)
                if said.is_empty() {
                    said.extend(bulk_note(&a.name, *min, *max, &octaves()));
                }
                if said.is_empty() {
                    said.extend(below_step_note(&a.name, &a.values, *min, *max));
                }
                // How much of the area-weighted total (what splats by the attribute add
                // up: a column density's mass) the 16-bit steps lose at particles'
                // resolution, where clusters keep their exact means.
                let area = |i: usize| -> f64 {
                    let r = match &radii {
                        Some(r) => r[i],
                        None => species[usize::from(species_index[i])].radius,
                    };
                    f64::from(r) * f64::from(r)
                };
                let lost = (!said.is_empty())
                    .then(|| quantized_total_loss(&a.values, area, *min, *max))
                    .flatten();
                if let Some(lost) = lost {
                    said.push(format!(
                        "attribute {name}: at particles' resolution its 16-bit steps change \
                         the area-weighted total that splats by the attribute add up (a \
                         column density's mass) by {pct:.1}%, while clusters keep their \
                         exact means: such an image's total depends on --screen-error",
                        name = a.name,
                        pct = lost * 100.0
                    ));
                }
            }
            notes.extend(said);
        }
    }
    // Further attributes spanning decades lose them as the first would, unless kept as
    // their logarithms.
    for (e, column) in h.extra_attributes.iter().zip(further) {
        if e.info.log10 {
            continue;
        }
        // Ids (of molecules) are told by their whole numbers, as for the first: no
        // logarithm to suggest.
        let whole = column.values.iter().all(|v| v.fract() == 0.0);
        let octaves = std::cell::OnceCell::new();
        let octaves = || octaves.get_or_init(|| Octaves::of(&column.values)).clone();
        let (note, ids) = extra_range_note(
            &e.info.name,
            e.info.min,
            e.info.max,
            whole,
            &logged,
            &octaves,
        );
        let said = note.is_some();
        notes.extend(note);
        // A column from 0 whose values above 0 fall below a step, as for the first, and
        // one whose few far values stretch its range.
        if !ids {
            let bulk = (!said)
                .then(|| bulk_note(&e.info.name, e.info.min, e.info.max, &octaves()))
                .flatten();
            let below = bulk
                .is_none()
                .then(|| below_step_note(&e.info.name, &column.values, e.info.min, e.info.max))
                .flatten();
            notes.extend(bulk.into_iter().chain(below));
        }
    }
    notes.extend(elements_in_other_units_note(
        frame.units.as_deref(),
        &species,
        &options.radii,
    ));
    let (lo, hi, far) = survey_positions(&frame.positions, frame.simulation_box.as_ref());
    notes.extend(position_notes(
        lo,
        hi,
        frame.positions.len() as u64,
        &species,
        far,
        frame.simulation_box.as_ref(),
        Some(&crate::species::counts(species.len(), species_index)),
        &options.radii,
    ));
    drop_default_radius_note_said_twice(&mut notes);
    notes.extend(delta_n_note(h.params.delta_n, h.level_count()));
    notes.extend(precision_note(
        h.max_position_error,
        h.params.position_bits,
        &species,
    ));
    let mut metadata = base_metadata(frame, source, options);
    metadata.species = species;
    metadata.max_position_error = h.max_position_error;
    let t1 = Instant::now();
    progress.stage("writing", None, "bytes");
    h.write(output, metadata)?;
    progress.finish_stage();
    let write_time = t1.elapsed();
    let file_size = std::fs::metadata(output).map(|m| m.len()).unwrap_or(0);
    Ok(ConvertReport {
        particles: h.particle_count() as u64,
        levels: h.level_count(),
        nodes: h.nodes.len(),
        max_position_error: h.max_position_error,
        read_time: Duration::ZERO,
        build_time,
        write_time,
        file_size,
        notes,
        frame: None,
    })
}

/// A note where 8-bit positions (`--precision u8`) are off by more than a twentieth of
/// the smallest particle's radius: grains of 0.5 mm were placed within 44 µm, 9 % of their
/// radius, with no word beside the error's figure.
pub(crate) fn precision_note(
    max_error: f64,
    position_bits: u32,
    species: &[mdlod_format::meta::Species],
) -> Option<String> {
    let smallest = species
        .iter()
        .map(|s| s.smallest_radius())
        .filter(|r| *r > 0.0)
        .min_by(f32::total_cmp)?;
    let share = max_error / f64::from(smallest);
    (position_bits < 16 && share > 0.05 && share.is_finite()).then(|| {
        format!(
            "{position_bits}-bit positions are off by up to {max_error:.2e}, {:.0} % of the \
             smallest particle's radius ({smallest}): --precision u16, the default, places \
             them 256 times closer",
            share * 100.0
        )
    })
}

/// How far outside its box, in box lengths (the box's largest extent), a particle must
/// lie to be noted as lost.
const FAR_OUTSIDE_BOXES: f32 = 10.0;

/// Where particles lie far outside the box (`simulation_box`'s axis-aligned bounds):
/// how many (when counted) and the farthest one's position (when known), or `None`.
pub(crate) struct FarOutside {
    pub count: Option<usize>,
    /// The farthest distance outside the box's bounds.
    pub beyond: f32,
    pub farthest: Option<[f32; 3]>,
}

/// In one pass over `positions`: their bounds (infinite for none), and those farther
/// outside the box than [`FAR_OUTSIDE_BOXES`] (none counted without a usable box).
pub(crate) fn survey_positions(
    positions: &[[f32; 3]],
    simulation_box: Option<&mdlod_format::meta::SimulationBox>,
) -> ([f32; 3], [f32; 3], Option<FarOutside>) {
    // The box's bounds and how far outside them a particle is lost.
    let far_box = simulation_box.and_then(|b| {
        let (blo, bhi) = crate::chunked::box_bounds(b);
        let edge = (0..3).map(|k| bhi[k] - blo[k]).fold(0.0f32, f32::max);
        (edge > 0.0 && edge.is_finite()).then_some((blo, bhi, FAR_OUTSIDE_BOXES * edge))
    });
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let mut far: Option<FarOutside> = None;
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
        let Some((blo, bhi, limit)) = far_box else {
            continue;
        };
        let d = (0..3)
            .map(|k| (blo[k] - p[k]).max(p[k] - bhi[k]))
            .fold(0.0f32, f32::max);
        if d > limit {
            let f = far.get_or_insert(FarOutside {
                count: Some(0),
                beyond: 0.0,
                farthest: None,
            });
            f.count = f.count.map(|c| c + 1);
            if d > f.beyond {
                f.beyond = d;
                f.farthest = Some(*p);
            }
        }
    }
    (lo, hi, far)
}

/// A note on particles reaching well outside a periodic box (more than a tenth of its
/// edge along a periodic axis): unwrapped coordinates, which `--wrap` puts back into the
/// cell (a forgotten wrap frames a box several times the cell's size).
fn outside_periodic_note(
    lo: [f32; 3],
    hi: [f32; 3],
    b: &mdlod_format::meta::SimulationBox,
) -> Option<String> {
    let periodic = b.periodic?;
    let (blo, bhi) = crate::chunked::box_bounds(b);
    let mut reach = Vec::new();
    for k in (0..3).filter(|&k| periodic[k]) {
        let edge = bhi[k] - blo[k];
        if !(edge > 0.0 && edge.is_finite()) {
            continue;
        }
        let out = (blo[k] - lo[k]).max(hi[k] - bhi[k]) / edge;
        if out > 0.1 {
            reach.push(format!(
                "{out:.2} box lengths along {} ({} to {} against the box's {} to {})",
                ["x", "y", "z"][k],
                lo[k],
                hi[k],
                blo[k],
                bhi[k]
            ));
        }
    }
    (!reach.is_empty()).then(|| {
        format!(
            "the particles reach outside the periodic box: {}: unwrapped coordinates? \
             --wrap wraps them into the cell",
            reach.join(", ")
        )
    })
}

/// A note where the box has no width along an axis the particles spread along (a
/// header's `5 5` for data spanning 23 Å): the box, not the data, is two-dimensional,
/// and every particle lies outside it.
fn flat_box_note(
    lo: [f32; 3],
    hi: [f32; 3],
    b: &mdlod_format::meta::SimulationBox,
) -> Option<String> {
    let (blo, bhi) = crate::chunked::box_bounds(b);
    let spans: Vec<String> = (0..3)
        .filter(|&k| bhi[k] - blo[k] == 0.0 && hi[k] > lo[k])
        .map(|k| format!("{} from {} to {}", ["x", "y", "z"][k], lo[k], hi[k]))
        .collect();
    (!spans.is_empty()).then(|| {
        format!(
            "the box has no width along {} the particles spread along ({}): a box read \
             wrong? The particles lie outside it (the file keeps the box as given)",
            if spans.len() == 1 { "an axis" } else { "axes" },
            spans.join(", ")
        )
    })
}

/// More species than a figure tells apart: [`position_notes`] asks whether they are ids.
const MANY_SPECIES: usize = 1000;

/// How many mean spacings a radius may span before [`oversized_note`] speaks: a
/// species of one radius (an element's, or one given), whose atoms never reach past a
/// spacing or two (a dense liquid's oxygen is a third of one; the same data in nm,
/// 3.4 of them); a species of particles of their own sizes (an SPH run's smoothing
/// lengths reach several spacings of the whole box where it is sparse), 20.
const OVERSIZED_SPACINGS: f64 = 2.5;
const OVERSIZED_SPACINGS_OWN_SIZES: f64 = 20.0;

/// A note on radii far larger than the particles' mean spacing (the volume, area or
/// length their centres' box spans, per particle, to the power of its dimension): the
/// spheres melt into one blob. The usual cause is data in other units than the radius's
/// (nanometre data in metres takes element radii of angströms, 10^9 times too large).
fn oversized_note(
    lo: [f32; 3],
    hi: [f32; 3],
    count: u64,
    species: &[mdlod_format::meta::Species],
    species_counts: Option<&[u64]>,
) -> Option<String> {
    let spacing = mean_spacing(lo, hi, count)?;
    // Where each species' count is known, its spheres are measured against the spacing
    // of its own particles: a few large grains among many small ones (an intruder in a
    // granular bed, a colloid among solvent) overlap nothing.
    let own_spacing = |i: usize| match species_counts {
        Some(c) => mean_spacing(lo, hi, c.get(i).copied().unwrap_or(0)),
        None => Some(spacing),
    };
    let over: Vec<(String, f64, f64)> = species
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let limit = match s.radius_range {
                Some(_) => OVERSIZED_SPACINGS_OWN_SIZES,
                None => OVERSIZED_SPACINGS,
            };
            let own = own_spacing(i)?;
            (f64::from(s.radius) > limit * own).then(|| {
                (
                    format!("{} ({})", s.name, radius_text(s.radius)),
                    f64::from(s.radius) / own,
                    own,
                )
            })
        })
        .collect();
    // The figures of the species most over its own spacing.
    let (_, ratio, spacing) = *over.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let over: Vec<String> = over.into_iter().take(3).map(|(s, _, _)| s).collect();
    Some(format!(
        "the radi{} {} {} {} times the mean spacing of those particles ({}, from the box \
         around all of them): the spheres overlap into one blob. If the data is in other units than the \
         radii (data in nanometres, radii in ångströms), give --radius NAME=R in the data's \
         own units (about half the spacing)",
        if over.len() == 1 { "us of" } else { "i of" },
        over.join(", "),
        if over.len() == 1 { "is" } else { "are up to" },
        readable(ratio, 1),
        readable(spacing, 4)
    ))
}

/// Species drawn at the default radius smaller than this share of the particles' mean
/// spacing draw as scattered dots: coarse-grained beads (a Martini bilayer's are about
/// five ångströms apart, a tenth of it at 0.5), where atoms of type numbers in metal
/// units (a spacing of two or three ångströms) stay above it.
const UNDERSIZED_SPACING: f64 = 0.15;

/// The particles' mean spacing: the volume, area or length their centres' box `lo..hi`
/// spans, per particle, to the power of its dimension; `None` for fewer than two or no
/// extent. The dimension is the most axes whose extents each reach the spacing they
/// give: a sheet relaxed a thousandth of an ångström off its plane spans an area, not a
/// volume (over its volume its spacing came out 0.22 where its atoms stand 2.5 apart).
fn mean_spacing(lo: [f32; 3], hi: [f32; 3], count: u64) -> Option<f64> {
    if count < 2 {
        return None;
    }
    let mut extent: Vec<f64> = (0..3)
        .map(|k| f64::from(hi[k]) - f64::from(lo[k]))
        .collect();
    extent.sort_by(|a, b| b.total_cmp(a));
    let widest = extent[0];
    if !(widest.is_finite() && widest > 0.0) {
        return None;
    }
    (1..=3)
        .rev()
        .map(|d| {
            let spread = &extent[..d];
            (
                spread,
                (spread.iter().product::<f64>() / count as f64).powf(1.0 / d as f64),
            )
        })
        .find(|(spread, spacing)| {
            let narrowest = spread[spread.len() - 1];
            spread.len() == 1 || (narrowest > 0.0 && narrowest >= *spacing)
        })
        .map(|(_, spacing)| spacing)
}

/// Radii below this (and coordinates below ten times it) are noted as too small for the
/// renderer's single precision: squared, with the view's arithmetic around them, they
/// fall below its normal numbers.
const TINY_LENGTH: f32 = 1e-18;

/// A radius as written (5, 1.28), in powers of ten where plain digits would run long
/// (4e-18, not 0.000000000000000004).
fn radius_text(r: f32) -> String {
    match (1e-4..1e7).contains(&r.abs()) || r == 0.0 {
        true => format!("{r}"),
        false => format!("{r:e}"),
    }
}

/// `x` as a plain number where it reads so (4.3, 1.157), with `digits` decimals, and in
/// powers of ten beyond (a spacing of 9.6e19 printed whole took twenty digits).
fn readable(x: f64, digits: usize) -> String {
    if (1e-3..1e5).contains(&x.abs()) {
        format!("{x:.digits$}")
    } else {
        format!("{x:.digits$e}")
    }
}

/// A note on species that took the default radius (named by type numbers or labels, no
/// `--radius`) far below the particles' mean spacing: the picture shows scattered dots
/// where the user expects a material.
fn undersized_note(
    lo: [f32; 3],
    hi: [f32; 3],
    count: u64,
    species: &[mdlod_format::meta::Species],
    given_radii: &[(String, f32)],
) -> Option<String> {
    let spacing = mean_spacing(lo, hi, count)?;
    let default = crate::species::DEFAULT_RADIUS;
    // (A radius given as --radius is the user's, even where it equals the default.)
    let small: Vec<&str> = species
        .iter()
        .filter(|s| {
            s.radius == default
                && s.radius_range.is_none()
                && crate::species::element(&s.name).is_none()
                && !given_radii.iter().any(|(name, _)| name == &s.name)
        })
        .map(|s| s.name.as_str())
        .collect();
    if small.is_empty() || f64::from(default) >= UNDERSIZED_SPACING * spacing {
        return None;
    }
    let shown: Vec<&str> = small.iter().take(4).copied().collect();
    let more = if small.len() > 4 { ", ..." } else { "" };
    let half = 0.5 * spacing;
    let digits = if half >= 10.0 { 0 } else { 1 };
    let share = f64::from(default) / spacing;
    Some(format!(
        "species {}{more}: drawn at the default radius {default}, {} of the particles' \
         mean spacing ({}, from the box around them), as scattered dots. If they \
         are larger (coarse-grained beads in ångströms, a radius in other units), give each \
         its size: --radius {}=R, about half the spacing ({}) for a dense \
         material; a dilute gas is drawn as it is",
        shown.join(", "),
        match share >= 0.01 {
            true => format!("{share:.2}"),
            false => format!("{share:.1e}"),
        },
        readable(spacing, 3),
        shown[0],
        readable(half, digits),
    ))
}

/// A δn asked for past the levels below the top node: every node then encodes (and is
/// drawn with) the particles themselves, and the file records the δn in effect.
pub(crate) fn delta_n_note(asked: u32, levels: usize) -> Option<String> {
    let below_top = levels.saturating_sub(1);
    (asked as usize > below_top && below_top > 0).then(|| {
        format!(
            "--delta-n {asked}: the hierarchy has {below_top} level{} below its top node, so every node encodes the particles' level and the file records --delta-n {below_top}",
            if below_top == 1 { "" } else { "s" }
        )
    })
}

/// Notes on positions that will not draw as the user expects, from the particles'
/// bounds `lo..hi`: coordinates so large that single precision (in which positions are
/// read and stored) snaps them to a grid coarse against the particles' size (a galaxy
/// zoom in comoving coordinates far from the origin), and particles far outside the box
/// (lost atoms of a run that blew up), which the view's fit includes.
// (Each argument is a fact of the frame the notes weigh; a struct would only name them
// twice.)
#[allow(clippy::too_many_arguments)]
pub(crate) fn position_notes(
    lo: [f32; 3],
    hi: [f32; 3],
    count: u64,
    species: &[mdlod_format::meta::Species],
    far: Option<FarOutside>,
    simulation_box: Option<&mdlod_format::meta::SimulationBox>,
    species_counts: Option<&[u64]>,
    given_radii: &[(String, f32)],
) -> Vec<String> {
    let mut notes = Vec::new();
    // Lost atoms far outside the box stretch the bounds the mean spacing is measured in
    // (three of them put a lattice of spacing 1 at 53): the box's part of the bounds,
    // and the particles less them, stand in.
    let (slo, shi, scount) = match (far.as_ref().and_then(|f| f.count), simulation_box) {
        (Some(lost), Some(b)) => {
            let (blo, bhi) = crate::chunked::box_bounds(b);
            (
                std::array::from_fn(|k| lo[k].max(blo[k])),
                std::array::from_fn(|k| hi[k].min(bhi[k])),
                count.saturating_sub(lost as u64),
            )
        }
        _ => (lo, hi, count),
    };
    notes.extend(oversized_note(slo, shi, scount, species, species_counts));
    notes.extend(undersized_note(slo, shi, scount, species, given_radii));
    notes.extend(crate::species::atom_name_notes(
        species.iter().map(|s| s.name.as_str()),
    ));
    notes.extend(crate::species::bead_name_note(
        species.iter().map(|s| (s.name.as_str(), s.radius)),
    ));
    notes.extend(crate::species::lower_case_type_note(
        species.iter().map(|s| (s.name.as_str(), s.radius)),
    ));
    // Thousands of species: ids (of molecules, residues, clusters) read as species.
    if species.len() > MANY_SPECIES {
        notes.push(format!(
            "{} species ({}, {}, ...): a molecule, residue or cluster id read as the species \
             (an XYZ file's first column, or --species-column)? Each takes a colour of the \
             palette; ids are better kept as an attribute (--attribute), which colours and \
             hides by ranges (--hide-by)",
            species.len(),
            species[0].name,
            species[1].name
        ));
    }
    if far.is_none() {
        notes.extend(simulation_box.and_then(|b| outside_periodic_note(lo, hi, b)));
    }
    notes.extend(simulation_box.and_then(|b| flat_box_note(lo, hi, b)));
    // A box single precision cannot hold (a damaged header's 1e39): kept, but no cell
    // drawn from it.
    if let Some(b) = simulation_box {
        let reach = [b.origin, b.a, b.b, b.c]
            .iter()
            .flatten()
            .fold(0f64, |m, v| {
                if v.is_nan() {
                    f64::INFINITY
                } else {
                    m.max(v.abs())
                }
            });
        if reach > f64::from(crate::hierarchy::MAX_COORDINATE) {
            notes.push(format!(
                "the box reaches {reach:.3e}, past ±{:e}, where single precision cannot hold \
                 its extent (a damaged header?): the file keeps it, but `render --cell` cannot \
                 draw it",
                crate::hierarchy::MAX_COORDINATE
            ));
        }
    }
    let largest = lo.iter().chain(&hi).map(|v| v.abs()).fold(0.0f32, f32::max);
    // (A species of particles of their own sizes: its smallest particle's, not its mean.)
    let smallest_radius = species
        .iter()
        .map(mdlod_format::meta::Species::smallest_radius)
        .fold(f32::INFINITY, f32::min);
    // The spacing of single-precision numbers near the largest coordinate.
    // (The power of two at or below it, times the machine epsilon.)
    let step = f32::from_bits(largest.to_bits() & 0x7f80_0000) * f32::EPSILON;
    if largest.is_finite() && smallest_radius.is_finite() && step > 0.05 * smallest_radius {
        let share = match step / smallest_radius {
            r if r < 10.0 => format!("{:.0}% of", 100.0 * r),
            r => format!("{r:.1e} times"),
        };
        // Data spanning about as far as it reaches from the origin is not helped by a
        // shift: its radius is what is out of scale (a radius of 0.5 for data in cm).
        let span = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
        let remedy = if far.is_some() {
            // The radius fits the box; lost particles set the reach.
            "these coordinates are those of particles far outside the box (below): leave \
             them out of the input, and the rest keep their digits"
                .to_string()
        } else if species
            .iter()
            .any(|s| s.radius_range.is_some_and(|[lo, _]| lo <= smallest_radius))
        {
            // Particles of their own sizes spanning decades (smoothing lengths): the
            // smallest are what single precision cannot place, not a radius to give.
            "the smallest particles are finer than single precision resolves this far from \
             the origin (a dense core): shift the data so that the origin lies at them, or \
             convert their region apart with coordinates relative to its centre"
                .to_string()
        } else if span > 0.25 * largest {
            format!(
                "the radius is tiny beside the data's extent ({span:.3e}): give --radius \
                 NAME=R in the data's own units (about the particles' spacing)"
            )
        } else {
            "shift the data near the origin (subtract its centre) before converting".to_string()
        };
        notes.push(format!(
            "coordinates reach {largest:.3e}, where single precision (in which positions are \
             read and stored) holds steps of {step:.2e}, {share} the smallest radius \
             ({smallest_radius}): particles snap to a grid (the position error is measured \
             after it); {remedy}"
        ));
    }
    // Lengths so small that their squares leave single precision's normal numbers
    // (1.2e-38), in which the renderer intersects rays with spheres: metres of atoms
    // (1e-10) draw, 1e-20 draws streaked and 1e-22 not at all, while the file verifies.
    if smallest_radius.is_finite()
        && smallest_radius > 0.0
        && (smallest_radius < TINY_LENGTH || (largest > 0.0 && largest < 10.0 * TINY_LENGTH))
    {
        notes.push(format!(
            "lengths this small (coordinates up to {largest:.3e}, radii from \
             {smallest_radius:.3e}) square below single precision's normal numbers, in which \
             the renderer works: spheres draw wrongly or not at all. Convert in a smaller \
             length unit (nanometres or ångströms, not metres: the coordinates and radii \
             times 1e9 or 1e10)"
        ));
    }
    if let Some(f) = far {
        let many = match f.count {
            Some(1) => "1 particle lies".to_string(),
            Some(n) => format!("{n} particles lie"),
            None => "particles lie".to_string(),
        };
        let at = f
            .farthest
            .map(|p| format!(", the farthest at ({}, {}, {})", p[0], p[1], p[2]))
            .unwrap_or_default();
        // Most of the particles outside: the box is what is wrong (a header's stale box).
        let cause = if f
            .count
            .is_some_and(|n| (n as u64).saturating_mul(2) > count)
        {
            "most of the frame: is the box the file records not the data's (written before \
             the data)?"
        } else {
            "lost atoms of a run that blew up?"
        };
        notes.push(format!(
            "{many} more than {FAR_OUTSIDE_BOXES} box lengths outside the box (up to {:.3e} \
             beyond it{at}): {cause} The hierarchy includes them: the clusters spanning them quantize their members' positions more \
             coarsely (the summary's position error grows); a fitted view leaves them out, \
             `render --fit-all` includes them",
            f.beyond
        ));
    }
    notes
}

/// Refuses a species whose radius from the input is zero, below or not a number, unless
/// `options` override it; `source` and `timestep` place the frame for the message.
pub fn check_radii(
    species: &[crate::frame::SpeciesName],
    options: &ConvertOptions,
    source: Option<&SourceInfo>,
    timestep: Option<u64>,
) -> Result<(), ConvertError> {
    let Some((name, radius)) = crate::species::unusable_radius(species, &options.radii) else {
        return Ok(());
    };
    Err(ConvertError::UnusableRadius(Box::new(UnusableRadius {
        place: FramePlace::of(source, timestep),
        species: name.to_string(),
        radius,
        format: source.and_then(|s| crate::readers::format_of_file(Path::new(&s.path))),
        particle: None,
    })))
}

/// [`UnusableRadius`] with the first particle of its species whose own size is unusable,
/// where `frame` gives particles their own sizes (a GSD frame's diameters).
fn with_particle(e: ConvertError, frame: &Frame, options: &ConvertOptions) -> ConvertError {
    let ConvertError::UnusableRadius(mut u) = e else {
        return e;
    };
    if let Some(radii) = &frame.radii {
        let of_species: Vec<bool> = frame
            .species
            .iter()
            .map(|s| crate::species::renamed(&options.species_names, &s.name) == u.species)
            .collect();
        let usable = |r: f32| r.is_finite() && r > 0.0;
        let theirs = || {
            frame
                .species_index
                .iter()
                .zip(radii)
                .enumerate()
                .filter(|(_, (&s, _))| of_species.get(usize::from(s)) == Some(&true))
        };
        // Named where the species' particles have sizes of their own, some usable (a
        // list of one size, 0, has no particle to name).
        if theirs().any(|(_, (_, &r))| usable(r)) {
            u.particle = theirs().find(|(_, (_, &r))| !usable(r)).map(|(i, _)| i);
        }
    }
    ConvertError::UnusableRadius(u)
}

/// Refuses a box with a coordinate that is not finite (`-1e308 1e308` bounds overflow
/// their extent; a reader's NaN), naming the input, before any particle is built: it
/// could not be written.
pub fn check_box(
    simulation_box: Option<&crate::frame::SimulationBox>,
    place: impl Fn() -> FramePlace,
) -> Result<(), ConvertError> {
    let Some(b) = simulation_box else {
        return Ok(());
    };
    for (name, v) in [("origin", b.origin), ("a", b.a), ("b", b.b), ("c", b.c)] {
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(ConvertError::BadBox {
                place: place(),
                problem: format!("its {name} vector holds {x}"),
            });
        }
    }
    // Its far corner, which a view and the cell's drawing reach, too.
    let corner: Vec<f64> = (0..3)
        .map(|k| b.origin[k] + b.a[k] + b.b[k] + b.c[k])
        .collect();
    if let Some(x) = corner.iter().find(|x| !x.is_finite()) {
        return Err(ConvertError::BadBox {
            place: place(),
            problem: format!("its far corner, origin + a + b + c, reaches {x}"),
        });
    }
    Ok(())
}

/// The name a file gives the attribute the input calls `name`: `log10(name)` when its
/// logarithm is stored ([`ConvertOptions::attribute_log10`]).
pub fn attribute_name(name: &str, options: &ConvertOptions) -> String {
    if options.attribute_log10 {
        format!("log10({name})")
    } else {
        name.to_string()
    }
}

/// The notes on where the species' radii come from: [`radius_override_notes`] and
/// [`default_radius_note`], for a build whole or in chunks.
pub(crate) fn radius_notes(names: &[SpeciesName], overrides: &[(String, f32)]) -> Vec<String> {
    let mut notes = radius_override_notes(names, overrides);
    notes.extend(default_radius_note(names, overrides));
    notes
}

/// Notes for each `--radius` that replaces sizes the input gives a species: its
/// particles' own sizes (a dump's `radius` or `diameter` column, GSD diameters) or the
/// species' one size (an MMPLD list's radius). `--radius` reads as a default or a scale
/// to some; it replaces.
pub fn radius_override_notes(names: &[SpeciesName], overrides: &[(String, f32)]) -> Vec<String> {
    names
        .iter()
        .filter_map(|s| {
            let (by, r) = crate::species::radius_override_named(overrides, &s.name)?;
            let given = match (s.radius_range, s.radius) {
                (Some((lo, hi)), _) if lo != hi => {
                    format!("the sizes the input gives its particles (radii {lo} to {hi})")
                }
                (Some((own, _)), _) | (None, Some(own)) if own != r => {
                    format!("the radius the input gives it ({own})")
                }
                _ => return None,
            };
            Some(format!(
                "species {}: --radius {by}={r} draws every particle of it at radius {r}, in \
                 place of {given}; leave --radius {by} out to keep the input's",
                s.name
            ))
        })
        .collect()
}

/// A note for species read as chemical elements, with radii in ångströms, in an input
/// whose lengths are in another unit: Lennard-Jones' σ (`units lj`), where bead names
/// that happen to be element symbols (P, H, S, C) draw at an element's size, blobs of
/// beads σ apart; micrometres (`units=um`), where silica colloids written `Si` drew 2.4
/// times too large.
pub(crate) fn elements_in_other_units_note(
    units: Option<&str>,
    species: &[mdlod_format::meta::Species],
    overrides: &[(String, f32)],
) -> Option<String> {
    let unit = units.and_then(non_angstrom_unit)?;
    let read: Vec<&mdlod_format::meta::Species> = species
        .iter()
        .filter(|s| {
            s.radius_range.is_none()
                && crate::species::radius_override(overrides, &s.name).is_none()
                && crate::species::element(&s.name).is_some_and(|(r, _)| r == s.radius)
        })
        .collect();
    let first = read.first()?;
    let read: Vec<String> = read
        .iter()
        .map(|s| format!("{} ({})", s.name, radius_text(s.radius)))
        .collect();
    let shown = match read.len() {
        0..=6 => read.join(", "),
        n => format!("{}, ... ({n} in all)", read[..5].join(", ")),
    };
    if unit == "σ" {
        return Some(format!(
            "species {shown}: read as chemical elements, with their radii in ångströms, while \
             the dump's units are lj (lengths in σ): if they are bead names, --radius {}=R \
             gives each its size (0.5 for beads of diameter σ), or --species-name to a name \
             that is no element's makes it a label, drawn at the default 0.5",
            first.name
        ));
    }
    Some(format!(
        "species {shown}: read as chemical elements, with their radii in ångströms, while \
         the input's lengths are in {unit}: --radius {}=R gives each its size in {unit} (a \
         colloid's, say), or --species-name to a name that is no element's makes it a label",
        first.name
    ))
}

/// The length unit of `units` (a LAMMPS unit style, or a unit a raw sidecar or an XYZ
/// comment names) where it is known and not ångströms, as said in a note; `None` for
/// ångström styles (`metal`, `real`) and for names not known.
fn non_angstrom_unit(units: &str) -> Option<&'static str> {
    length_unit_of(units).filter(|u| *u != "Å")
}

/// The length unit `units` names (a LAMMPS unit style, or a unit a raw sidecar or an XYZ
/// comment names), as notes and scale bars say it; `None` for names not known (a
/// sidecar's `Mpc/h`, which a scale bar shows as written).
pub fn length_unit_of(units: &str) -> Option<&'static str> {
    Some(match units.trim().to_ascii_lowercase().as_str() {
        "metal" | "real" | "angstrom" | "å" => "Å",
        "lj" => "σ",
        "si" | "m" => "m",
        "cgs" | "cm" => "cm",
        "mm" => "mm",
        "micro" | "um" | "µm" | "μm" | "micron" | "microns" | "micrometre" | "micrometer" => "µm",
        "nano" | "nm" => "nm",
        "electron" | "bohr" => "bohr",
        "pc" => "pc",
        "kpc" => "kpc",
        "mpc" => "Mpc",
        _ => return None,
    })
}

/// Drops [`default_radius_note`] where the note on species drawn at the default radius
/// far below the spacing (`undersized_note`) says it too, with more.
pub(crate) fn drop_default_radius_note_said_twice(notes: &mut Vec<String>) {
    if notes
        .iter()
        .any(|n| n.contains(": drawn at the default radius "))
    {
        notes.retain(|n| !n.contains(", the default: no size was read for them"));
    }
}

/// A note for species drawn at the default radius because nothing gives them a size
/// (`species::default_radius_species`): a granular dump without its `diameter` column
/// looks right at a glance, every grain of one size.
pub fn default_radius_note(names: &[SpeciesName], overrides: &[(String, f32)]) -> Option<String> {
    let mut plain = crate::species::default_radius_species(names, overrides);
    // In one order whatever order a frame lists them in (type numbers by value, then
    // names): a batch gathers like notes of its frames, and beads listed in six orders
    // gave six notes.
    plain.sort_by_key(|n| {
        (
            n.parse::<u64>().map_or((1, u64::MAX), |v| (0, v)),
            n.to_string(),
        )
    });
    let first = plain.first()?;
    // (A species column of molecule ids gives thousands.)
    let list = match plain.len() {
        0..=8 => plain.join(", "),
        n => format!("{}, ... ({n} in all)", plain[..6].join(", ")),
    };
    Some(format!(
        "species {list}: drawn at radius {}, the default: no size was read for them (a \
         `radius` or `diameter` column, or --radius {first}=R, gives them theirs)",
        crate::species::DEFAULT_RADIUS
    ))
}

/// A note for an attribute whose 16-bit linear steps erase its lowest decades: values
/// above 0 spanning more than four decades, stored as they are.
pub fn attribute_span_note(
    name: &str,
    min: f32,
    max: f32,
    options: &ConvertOptions,
    logged: &[String],
    octaves: &dyn Fn() -> Octaves,
) -> Option<String> {
    if options.attribute_log10 {
        return None;
    }
    // (Alone, the flag takes the first: an input's own attribute too, a raw sidecar's.)
    let flag = match logged.is_empty() {
        true => "--attribute-log10".to_string(),
        false => format!("--attribute-log10={name},{}", logged.join(",")),
    };
    span_note(
        name,
        min,
        max,
        &format!("{flag} keeps its logarithm, every decade alike"),
        octaves,
    )
}

/// The `--attribute-log10=` that keeps `name`'s logarithm beside those of `logged` (the
/// columns, by their input names, a conversion keeps as logarithms): naming `name` alone
/// would keep theirs linear.
pub fn log10_flag(name: &str, logged: &[String]) -> String {
    let mut names = logged.to_vec();
    names.push(name.to_string());
    format!("--attribute-log10={}", names.join(","))
}

/// The input names of the attributes `metadata` keeps as logarithms, the first's first.
pub fn logged_columns(metadata: &Metadata) -> Vec<String> {
    let inner = |n: &str| {
        n.strip_prefix("log10(")
            .and_then(|s| s.strip_suffix(')'))
            .unwrap_or(n)
            .to_string()
    };
    let first = metadata
        .attribute
        .iter()
        .filter(|_| metadata.attribute_log10)
        .map(|a| inner(&a.name));
    let further = metadata
        .attributes
        .iter()
        .filter(|a| a.log10)
        .map(|a| inner(&a.name));
    first.chain(further).collect()
}

/// The relative change 16-bit quantization over `[min, max]` makes to `Σ area(i) · v_i`
/// (`Some` from 1 % on): SPH column densities `m / (π h²)` spanning ten decades lost 44 %
/// of their mass at particles' resolution, silently.
pub fn quantized_total_loss(
    values: &[f32],
    area: impl Fn(usize) -> f64 + Sync,
    min: f32,
    max: f32,
) -> Option<f64> {
    use rayon::prelude::*;
    let info = mdlod_format::meta::AttributeInfo {
        name: String::new(),
        min,
        max,
        log10: false,
    };
    // (Measured against Σ area · |v|: a column of signed values may sum to about 0.)
    let (size, change) = values
        .par_iter()
        .enumerate()
        .map(|(i, &v)| {
            let a = area(i);
            let stored = f64::from(info.decode(info.encode(v)));
            (a * f64::from(v).abs(), a * (stored - f64::from(v)))
        })
        .reduce(|| (0.0, 0.0), |x, y| (x.0 + y.0, x.1 + y.1));
    let lost = (change / size).abs();
    (size > 0.0 && lost.is_finite() && lost >= 0.01).then_some(lost)
}

/// A note for a column from 0 (or below) whose values above 0 reach far below one 16-bit
/// step of its range: a kinetic energy with walls at rest, where most grains' values
/// read as 0 or one step, which [`attribute_span_note`] (values above 0 only) misses.
/// `None` where fewer than 1 % of the values above 0 are below a step.
pub fn below_step_note(name: &str, values: &[f32], min: f32, max: f32) -> Option<String> {
    if min > 0.0 || max.is_nan() || max <= 0.0 {
        return None;
    }
    let step = (f64::from(max) - f64::from(min)) / 65535.0;
    let (mut above, mut below, mut smallest) = (0u64, 0u64, f32::INFINITY);
    for &v in values.iter().filter(|v| **v > 0.0) {
        above += 1;
        if f64::from(v) < step {
            below += 1;
        }
        smallest = smallest.min(v);
    }
    (below > 0 && below * 100 >= above).then(|| {
        format!(
            "attribute {name}: {below} of the {above} values above 0 lie below one 16-bit \
             step ({step:.2e}) of its range {min} to {max} and read as 0 or one step (the \
             smallest is {smallest:e}); --attribute-log10 keeps every decade, but only of a \
             column whose values are all above 0, which this one's are not (a quantity \
             offset to stay above 0 in the simulation, such as ke + 1e-12 written by a \
             variable, can take it)"
        )
    })
}

/// For a column of whole numbers (ids of molecules, clusters), its note, in one pass over
/// `values`: where they span more than 16-bit steps tell apart, neighbouring values share
/// a step, so no colour or hidden range picks out one value; whole numbers within 65 536
/// of one another keep a step each, with nothing to say (`Some(None)`). `None` for a
/// column with fractions, whose span notes apply instead.
pub fn whole_numbers_note(
    name: &str,
    values: &[f32],
    min: f32,
    max: f32,
) -> Option<Option<String>> {
    // (Past 2^24 every single-precision number is whole: a quantity spanning decades,
    // not ids.)
    const WHOLE: f32 = 16_777_216.0;
    if !(min >= -WHOLE && max <= WHOLE) || values.iter().any(|v| v.fract() != 0.0) {
        return None;
    }
    let span = f64::from(max) - f64::from(min);
    if span.is_nan() || span <= 32767.5 {
        return Some(None);
    }
    if span <= 65535.0 {
        // Each value keeps a step of its own, but a step above a half puts an end
        // halfway between two values in the same step as one of them.
        return Some(Some(format!(
            "attribute {name} holds whole numbers from {min} to {max} (ids?), each in a 16-bit \
             step of its own (a step is {:.2}): --hide-attribute ends halfway between them \
             (299.5:300.5) may take in a neighbour or leave out the value they surround; \
             give whole-number ends (300:300)",
            span / 65535.0
        )));
    }
    Some(Some(format!(
        "attribute {name} holds whole numbers from {min} to {max} (ids?), more than 16 bits \
         tell apart (a step is {:.2}): neighbouring values share a colour and \
         --hide-attribute cannot pick out one value; a column of at most 65 536 distinct \
         values is kept exactly as species (--species-column), a molecule's type say rather \
         than its id",
        span / 65535.0
    )))
}

/// The note on a further attribute's range `min..max`: the ids note where its values are
/// all whole numbers (`whole`) that read as ids ([`whole_numbers_note`]), else its span's
/// ([`extra_span_note`]); and whether they read as ids.
pub(crate) fn extra_range_note(
    name: &str,
    min: f32,
    max: f32,
    whole: bool,
    logged: &[String],
    octaves: &dyn Fn() -> Octaves,
) -> (Option<String>, bool) {
    match whole
        .then(|| whole_numbers_note(name, &[], min, max))
        .flatten()
    {
        Some(ids) => (ids, true),
        None => (extra_span_note(name, min, max, logged, octaves), false),
    }
}

/// [`attribute_span_note`] of a further attribute (kept linearly).
pub fn extra_span_note(
    name: &str,
    min: f32,
    max: f32,
    logged: &[String],
    octaves: &dyn Fn() -> Octaves,
) -> Option<String> {
    span_note(
        name,
        min,
        max,
        &format!(
            "{} keeps its logarithm, every decade alike",
            log10_flag(name, logged)
        ),
        octaves,
    )
}

/// [`attribute_span_note`] of a column kept linearly, with `remedy` said last.
fn span_note(
    name: &str,
    min: f32,
    max: f32,
    remedy: &str,
    octaves: &dyn Fn() -> Octaves,
) -> Option<String> {
    let decades = (f64::from(max) / f64::from(min)).log10();
    // Values below a hundred steps lose digits: said where they are more than a few (a
    // score uniform from 0 to 1 reaches 1e-4 with a few values, which lose nothing much).
    let lossy = (f64::from(max) - f64::from(min)) / 65535.0 * 100.0;
    // (The octaves counted only where the range itself calls for a note.)
    let many = || octaves().share_below(lossy) >= 0.01;
    (min > 0.0 && decades > 4.0 && many()).then(|| {
        format!(
            "attribute {name} spans {decades:.1} decades ({min:e} to {max:e}), kept in 16-bit \
             steps of {:.2e}: the values below about {:.0e} lose their digits; {remedy}",
            (f64::from(max) - f64::from(min)) / 65535.0,
            (f64::from(max) - f64::from(min)) / 65535.0 * 100.0
        )
    })
}

/// A note for a column whose values but for a few at its ends lie within a few hundred of
/// its 16-bit steps: a contact force's spike of −2000 N among forces of ±0.02 N put them
/// all in one step, so colours and hidden ranges could not tell them apart (5 639
/// particles hidden by a range holding 2 974), with no word. `None` where the middle 98 %
/// (bounded to powers of two, [`Octaves::bulk`]) spans 256 steps or more.
pub fn bulk_note(name: &str, min: f32, max: f32, octaves: &Octaves) -> Option<String> {
    let step = (f64::from(max) - f64::from(min)) / 65535.0;
    let (lo, hi) = octaves.bulk()?;
    // (The bounds are of octaves: not past the range itself.)
    let (lo, hi) = (lo.max(f64::from(min)), hi.min(f64::from(max)));
    let steps = ((hi - lo) / step).ceil().max(1.0);
    (step > 0.0 && step.is_finite() && steps < 256.0).then(|| {
        let (lo, hi) = (lo as f32, hi as f32);
        format!(
            "attribute {name}: 98 % of its values lie between {lo:e} and {hi:e}, within \
             {steps:.0} of the 65 535 16-bit steps of its range {min:e} to {max:e}, which the \
             few far values at its ends stretch: colours and --hide-attribute ranges tell \
             those 98 % apart by {} only; a copy of the column clamped near them \
             in the simulation keeps them apart (in LAMMPS, `variable c atom \
             max(min({name},{hi:e}),{lo:e})` dumped as v_c)",
            match steps as u64 {
                1 => "one step".to_string(),
                n => format!("{n} steps"),
            }
        )
    })
}

/// How many of a column's values lie in each binary octave (by their `f32` exponent),
/// those above 0 and below it apart: enough to tell, once the range is known, whether the
/// values below some level are a few or many, or where most of them lie, over a frame
/// read whole or window by window.
#[derive(Clone, Debug, PartialEq)]
pub struct Octaves {
    counts: [u64; 256],
    /// Values above 0, counted in `counts`.
    positive: u64,
    /// Values below 0, by the octave of their magnitude.
    negative: [u64; 256],
    /// Values of 0 (either sign), or NaN.
    zero: u64,
}

impl Default for Octaves {
    fn default() -> Self {
        Octaves {
            counts: [0; 256],
            positive: 0,
            negative: [0; 256],
            zero: 0,
        }
    }
}

/// The share of a column's values at either end that [`Octaves::bulk`] leaves out: a
/// hundredth.
const BULK_TAIL: f64 = 0.01;

impl Octaves {
    /// The octaves of `values`.
    pub fn of(values: &[f32]) -> Octaves {
        use rayon::prelude::*;
        values
            .par_chunks(1 << 16)
            .map(|chunk| {
                let mut o = Octaves::default();
                for &v in chunk {
                    let e = ((v.to_bits() >> 23) & 0xff) as usize;
                    if v > 0.0 {
                        o.counts[e] += 1;
                        o.positive += 1;
                    } else if v < 0.0 {
                        o.negative[e] += 1;
                    } else {
                        o.zero += 1;
                    }
                }
                o
            })
            .reduce(Octaves::default, |mut a, b| {
                a.add(&b);
                a
            })
    }

    /// Adds `other`'s counts (another window's).
    pub fn add(&mut self, other: &Octaves) {
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += b;
        }
        for (a, b) in self.negative.iter_mut().zip(&other.negative) {
            *a += b;
        }
        self.positive += other.positive;
        self.zero += other.zero;
    }

    /// Bounds, to a power of two, of the values left once a hundredth of them at each end
    /// is set aside ([`BULK_TAIL`]): every such value lies within them. `None` for fewer
    /// than 100 values (a hundredth of them is not one).
    pub fn bulk(&self) -> Option<(f64, f64)> {
        // The octaves in order along the number line, each with its ends: the negative
        // ones from the largest magnitude down, 0, then the positive ones up.
        let edge = |e: usize| f64::from(f32::from_bits((e as u32) << 23));
        let top = |e: usize| match e {
            0 => f64::from(f32::MIN_POSITIVE),
            _ => 2.0 * edge(e),
        };
        let bins: Vec<(u64, f64, f64)> = (0..256)
            .rev()
            .map(|e| (self.negative[e], -top(e), -edge(e)))
            .chain(std::iter::once((self.zero, 0.0, 0.0)))
            .chain((0..256).map(|e| (self.counts[e], edge(e), top(e))))
            .filter(|(n, _, _)| *n > 0)
            .collect();
        let total: u64 = bins.iter().map(|(n, _, _)| n).sum();
        let tail = (total as f64 * BULK_TAIL).floor() as u64;
        if tail == 0 {
            return None;
        }
        // The octave holding the first value past the tail, from each end.
        fn past<'a>(
            mut order: impl Iterator<Item = &'a (u64, f64, f64)>,
            tail: u64,
        ) -> Option<(u64, f64, f64)> {
            let mut seen = 0;
            order
                .find(|(n, _, _)| {
                    seen += n;
                    seen > tail
                })
                .copied()
        }
        let (_, lo, _) = past(bins.iter(), tail)?;
        let (_, _, hi) = past(bins.iter().rev(), tail)?;
        Some((lo, hi))
    }

    /// The share of the values above 0 that may lie below `x`: those of every octave
    /// that begins below it (so at most twice as far below as the octave's width).
    pub fn share_below(&self, x: f64) -> f64 {
        if self.positive == 0 {
            return 0.0;
        }
        let below: u64 = self
            .counts
            .iter()
            .enumerate()
            .filter(|(e, _)| f64::from(f32::from_bits((*e as u32) << 23)) < x)
            .map(|(_, c)| c)
            .sum();
        below as f64 / self.positive as f64
    }
}

/// The range of the base-10 logarithms of attribute values (of particles from `first`
/// on), as a file stores them with `attribute_log10`: the logarithms of the values'
/// smallest and largest (`log10` is monotonic, so no value's logarithm is taken here); a
/// value not above 0 (or not finite) is an error naming the particle.
pub fn log10_range(
    values: &[f32],
    first: usize,
    name: &str,
    source: Option<&SourceInfo>,
) -> Result<(f32, f32), ConvertError> {
    let bad = crate::readers::first_index(values.len(), |i: usize| {
        !(values[i] > 0.0 && values[i].is_finite())
    });
    if let Some(i) = bad {
        return Err(ConvertError::AttributeNotPositive {
            place: FramePlace::of(source, None),
            name: name.to_string(),
            index: first + i,
            value: values[i],
        });
    }
    let (lo, hi) = par_min_max(values);
    Ok((lo.log10(), hi.log10()))
}

/// The smallest and largest of `values` (infinite and negative infinite when there are
/// none), over every core.
pub(crate) fn par_min_max(values: &[f32]) -> (f32, f32) {
    use rayon::prelude::*;
    values
        .par_iter()
        .fold(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |(lo, hi), &v| (lo.min(v), hi.max(v)),
        )
        .reduce(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        )
}

/// Refuses more attributes than a file keeps before any input is read (`input` names
/// the inputs).
pub fn check_attribute_count(
    read: &crate::readers::ReadOptions,
    input: &str,
) -> Result<(), ConvertError> {
    match too_many_attributes(read.extra_attributes.len()) {
        None => Ok(()),
        Some(problem) => Err(ConvertError::Attributes {
            place: FramePlace {
                path: input.to_string(),
                frame: None,
                timestep: None,
            },
            problem,
        }),
    }
}

/// Why `extras` further attributes are more than a file keeps; `None` where they are not.
pub(crate) fn too_many_attributes(extras: usize) -> Option<String> {
    (extras > mdlod_format::MAX_EXTRA_ATTRIBUTES).then(|| {
        format!(
            "{} attributes (--attribute): a file keeps at most {}",
            extras + 1,
            mdlod_format::MAX_EXTRA_ATTRIBUTES + 1
        )
    })
}

/// Why further attributes of these names cannot be kept beside the `first`: without
/// one, named twice (or as the first), or more than the format holds. `None` where
/// they can.
pub(crate) fn extra_names_problem(first: Option<&str>, extras: &[&str]) -> Option<String> {
    if first.is_none() && !extras.is_empty() {
        Some("further attributes need a first (the first --attribute)".to_string())
    } else if let Some((_, e)) = extras
        .iter()
        .enumerate()
        .find(|(k, e)| first == Some(**e) || extras[..*k].contains(e))
    {
        Some(format!("attribute {e} is given twice"))
    } else {
        too_many_attributes(extras.len())
    }
}

/// Refuses extra attributes a conversion cannot keep: of another length than the frame,
/// or as [`extra_names_problem`] says.
fn check_extras(
    frame: &Frame,
    extras: &[crate::frame::Attribute],
    source: Option<&SourceInfo>,
    options: &ConvertOptions,
) -> Result<(), ConvertError> {
    let place = || FramePlace::of(source, frame.timestep);
    let names: Vec<&str> = extras.iter().map(|e| e.name.as_str()).collect();
    let problem = if let Some(problem) = extra_log10_problem(names.len(), options) {
        Some(problem)
    } else if let Some(e) = extras.iter().find(|e| e.values.len() != frame.len()) {
        Some(format!(
            "attribute {} has {} values for {} particles",
            e.name,
            e.values.len(),
            frame.len()
        ))
    } else {
        extra_names_problem(frame.attribute.as_ref().map(|a| a.name.as_str()), &names)
    };
    match problem {
        Some(problem) => Err(ConvertError::Attributes {
            place: place(),
            problem,
        }),
        None => Ok(()),
    }
}

/// Why `options.extra_log10` cannot be taken with `further` further attributes: it asks
/// for the logarithm of one past them. `None` where it can.
pub fn extra_log10_problem(further: usize, options: &ConvertOptions) -> Option<String> {
    let k = options.extra_log10.iter().rposition(|&l| l)?;
    (k >= further).then(|| {
        format!(
            "the logarithm of further attribute {} is asked for, but {further} further \
             attributes are kept",
            k + 1
        )
    })
}

impl ConvertOptions {
    /// Whether further attribute `k` is kept as its logarithm ([`Self::extra_log10`]).
    pub fn extra_logged(&self, k: usize) -> bool {
        self.extra_log10.get(k).copied().unwrap_or(false)
    }
}

/// The name a file gives further attribute `k`, which the input calls `name`:
/// `log10(name)` where its logarithm is kept ([`ConvertOptions::extra_log10`]).
pub fn extra_attribute_name(name: &str, k: usize, options: &ConvertOptions) -> String {
    if options.extra_logged(k) {
        format!("log10({name})")
    } else {
        name.to_string()
    }
}

/// Why a frame of `particles` above the chunk size cannot take the magnitude `read` asks
/// for (`--attribute '|v|'`) from `dump`: a LAMMPS or XYZ frame's magnitude is read a
/// column at a time from the whole frame, while a frame this large is read in windows
/// (a GSD chunk's rows are taken in any part). `None` where it can.
pub fn chunked_magnitude_problem(
    dump: &crate::readers::DumpFile,
    read: &crate::readers::ReadOptions,
    particles: u64,
    chunk_points: usize,
) -> Option<String> {
    let inner = read
        .attribute
        .iter()
        .chain(&read.extra_attributes)
        .find_map(|a| crate::readers::magnitude_of(a))?;
    (dump.format() != crate::readers::InputFormat::Gsd).then(|| {
        format!(
            "the magnitude |{inner}| is taken over whole frames, and this frame's {particles} \
             particles are above the chunk size ({chunk_points}): `--chunk-points \
             {particles}` takes the frame whole where the memory limit allows it (it says so \
             where not); for frames larger still, write the magnitude into the dump as a \
             column of its own (LAMMPS: `variable speed atom sqrt(vx*vx+vy*vy+vz*vz)` and \
             `v_speed` in the dump's columns)"
        )
    })
}

/// The metadata of `frame` before its hierarchy is built (species, attribute range and
/// error bound are filled in by the build).
pub fn base_metadata(
    frame: &Frame,
    source: Option<SourceInfo>,
    options: &ConvertOptions,
) -> Metadata {
    Metadata {
        particles: frame.len() as u64,
        simulation_box: frame.simulation_box.clone(),
        timestep: frame.timestep,
        time: frame.time,
        units: frame.units.clone(),
        species: species_table(&frame.species, &options.radii),
        species_column: options.species_column.clone(),
        attribute: frame.attribute.as_ref().map(|a| AttributeInfo {
            name: attribute_name(&a.name, options),
            min: 0.0,
            max: 0.0,
            log10: false,
        }),
        attribute_log10: options.attribute_log10 && frame.attribute.is_some(),
        attributes: Vec::new(),
        radius: None,
        radius_log: None,
        source,
        build: BuildInfo {
            max_cluster_size: options.build.max_cluster_size,
            max_root_points: options.build.max_root_points,
            delta_n: options.build.delta_n,
            position_bits: options.build.position_bits,
            chunk_points: None,
        },
        max_position_error: 0.0,
        writer: format!("mdlod {}", env!("CARGO_PKG_VERSION")),
        input_options: options.input_options.clone(),
    }
}

/// A frame with the box, timestep, time and units of `info` and no particles.
pub fn header_of(info: &crate::readers::FrameInfo) -> Frame {
    Frame {
        simulation_box: info.simulation_box.clone(),
        timestep: info.timestep,
        time: info.time,
        units: info.units.clone(),
        ..Frame::default()
    }
}

/// A source that reads frame `k` of `dump` a window at a time, when its format allows
/// (binary dumps, raw arrays and GSD by ranges, uncompressed text by lines, `%` piece
/// sets piece by piece); `None` for compressed text, which is read whole.
pub fn window_source(
    dump: &crate::readers::DumpFile,
    k: usize,
    read: &crate::readers::ReadOptions,
    info: &crate::readers::FrameInfo,
) -> Option<Box<dyn crate::chunked::ParticleSource>> {
    let windows = if dump.reads_parts() {
        crate::chunked::Windows::Parts
    } else if dump.reads_text_windows() {
        crate::chunked::Windows::Text
    } else if dump.piece_paths().is_some() {
        crate::chunked::Windows::Pieces
    } else {
        return None;
    };
    Some(Box::new(DumpSource {
        path: dump.path().to_path_buf(),
        frame: k,
        options: read.clone(),
        particles: info.particles,
        simulation_box: info.simulation_box.clone(),
        text_header: (windows == crate::chunked::Windows::Text)
            .then(|| dump.header(k).ok())
            .flatten(),
        pieces: dump.piece_paths(),
        piece_headers: (windows == crate::chunked::Windows::Pieces)
            .then(|| dump.piece_headers(k))
            .flatten(),
        windows,
    }))
}

/// Which frame of a multi-frame input to convert.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FrameSelect {
    /// Frame `k` (0-based).
    Index(usize),
    /// The last frame.
    #[default]
    Last,
    /// Frame `n` from the end (1: the last), as `--frame -n` asks.
    FromEnd(usize),
}

/// A dump opened within the memory limit (see [`open_bounded`]).
pub struct BoundedDump {
    pub dump: crate::readers::DumpFile,
    /// The working file a large gzip input was decompressed into (`dump` reads it); for a
    /// `%` piece set, the working directory of its decompressed pieces.
    pub text: Option<PathBuf>,
    /// Its working directory, removed when this is dropped.
    _work: Option<tempfile::TempDir>,
}

/// Opens `input` as [`crate::readers::DumpFile::open`] does, except a large gzip input
/// (see `ChunkOptions::gzip_in_memory`: more compressed bytes than that, or more text
/// than [`crate::chunked::ChunkOptions::gzip_text_in_memory_max`], found by decompressing
/// no more than that into memory): that is decompressed as a stream into a working file
/// in a fresh directory under `chunks.temp_dir_for(output)`, and the dump reads the file,
/// a window at a time where a frame needs it, so memory stays within the limit. The
/// pieces of a `%` piece set are opened so one by one, the text limit holding for the
/// text of all the pieces kept in memory together.
pub fn open_bounded(
    input: &Path,
    chunks: &crate::chunked::ChunkOptions,
    output: &Path,
    progress: &dyn Progress,
) -> Result<BoundedDump, ConvertError> {
    if crate::readers::is_piece_pattern(input) {
        return open_pieces_bounded(input, chunks, output, progress);
    }
    let mut work = None;
    let limit = chunks.gzip_text_in_memory_max();
    let (dump, text) = open_piece_bounded(input, chunks, limit, output, &mut work, progress)?;
    Ok(BoundedDump {
        dump,
        text,
        _work: work,
    })
}

/// [`open_bounded`] of a `%` piece set: the pieces that are too large for memory are
/// decompressed into working files of one directory (the `text` of the result).
fn open_pieces_bounded(
    pattern: &Path,
    chunks: &crate::chunked::ChunkOptions,
    output: &Path,
    progress: &dyn Progress,
) -> Result<BoundedDump, ConvertError> {
    let mut work = None;
    let mut left = chunks.gzip_text_in_memory_max();
    let mut pieces = Vec::new();
    for piece in crate::readers::piece_paths(pattern)? {
        let (dump, _) = open_piece_bounded(&piece, chunks, left, output, &mut work, progress)?;
        left = left.saturating_sub(dump.text_in_memory());
        pieces.push(dump);
    }
    let dump = crate::readers::DumpFile::from_pieces(pattern, pieces)?;
    Ok(BoundedDump {
        dump,
        text: work.as_ref().map(|w| w.path().to_path_buf()),
        _work: work,
    })
}

/// Opens the file `input` in memory when it is not a gzip file over the limits (at most
/// `text_limit` bytes of text), else decompresses it into a working file in `work`
/// (made on first use) and opens that: the dump and the working file, if any.
fn open_piece_bounded(
    input: &Path,
    chunks: &crate::chunked::ChunkOptions,
    text_limit: u64,
    output: &Path,
    work: &mut Option<tempfile::TempDir>,
    progress: &dyn Progress,
) -> Result<(crate::readers::DumpFile, Option<PathBuf>), ConvertError> {
    let compressed = std::fs::metadata(input).map_or(0, |m| m.len());
    let large = compressed > chunks.gzip_in_memory_max() && crate::readers::is_gzip(input)?;
    if !large {
        if let Some(dump) = crate::readers::DumpFile::open_within(input, text_limit, progress)? {
            return Ok((dump, None));
        }
    }
    let dir = match work {
        Some(w) => w,
        None => {
            let parent = chunks.temp_dir_for(output);
            let w = tempfile::Builder::new()
                .prefix(".mdlod-convert-")
                .tempdir_in(&parent)
                .map_err(|e| ConvertError::Temp {
                    path: parent.clone(),
                    source: mdlod_format::files::temp_error(e),
                })?;
            work.insert(w)
        }
    };
    let name = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Named as the input less `.gz`, so that the format is told from the name as the
    // input's would be (else from the text); the pieces of a set have distinct names.
    let text = dir.path().join(
        name.strip_suffix(".gz")
            .map_or_else(|| format!("{name}.txt"), String::from),
    );
    let (_, cut) = crate::readers::gunzip_to_file(input, &text, progress)?;
    // (A working file: its index is of no use to a later run.)
    let _uncached = crate::readers::index_cache::IndexCache::suspend();
    let dump = crate::readers::DumpFile::open(&text)
        .map_err(|e| decompressed(input, Some(&text), e.into()))?;
    let dump = if cut { dump.with_gzip_cut(input) } else { dump };
    Ok((dump.named_as(input), Some(text)))
}

impl BoundedDump {
    /// Names the input in an error met while reading a decompressed working file.
    pub fn context(&self, input: &Path, e: ConvertError) -> ConvertError {
        decompressed(input, self.text.as_deref(), e)
    }
}

/// [`ConvertError::Decompressed`]'s message: `source`'s with the working file `text`
/// named as the line of `input`'s decompressed text it was.
fn decompressed_message(input: &Path, text: &Path, source: &ConvertError) -> String {
    let inner = source.to_string();
    let working = text.display().to_string();
    let line = inner
        .strip_prefix(&working)
        .and_then(|rest| rest.strip_prefix(':'))
        .and_then(|rest| {
            let digits = rest.len() - rest.trim_start_matches(|c: char| c.is_ascii_digit()).len();
            (digits > 0).then(|| (&rest[..digits], &rest[digits..]))
        });
    match line {
        Some((line, rest)) => format!(
            "{}: line {line} of its decompressed text{rest}",
            input.display()
        ),
        None => format!(
            "{} (decompressed): {}",
            input.display(),
            inner.replace(&working, "its decompressed text")
        ),
    }
}

/// `e`, met reading `text` (the working file `input` was decompressed into, if any).
fn decompressed(input: &Path, text: Option<&Path>, e: ConvertError) -> ConvertError {
    match text {
        Some(text) => ConvertError::Decompressed {
            input: input.to_path_buf(),
            text: text.to_path_buf(),
            inner: Box::new(e),
        },
        None => e,
    }
}

/// Reads one frame of `input` (any format [`crate::readers`] knows) and converts it. A
/// large gzip input is decompressed into a working file first ([`open_bounded`]).
pub fn convert_file(
    input: &Path,
    output: &Path,
    frame: FrameSelect,
    read: &crate::readers::ReadOptions,
    options: &ConvertOptions,
    progress: &dyn Progress,
) -> Result<ConvertReport, ConvertError> {
    check_attribute_count(read, &input.display().to_string())?;
    let t0 = Instant::now();
    let BoundedDump { dump, text, _work } = open_bounded(input, &options.chunks, output, progress)?;
    // Opening indexes the frames (a pass over a text dump): part of reading the input,
    // which the throughput printed from the report must include.
    let opened = t0.elapsed();
    // One processor's piece of a `%` set given alone reads that piece's particles only.
    let piece = match dump.piece_paths() {
        None => {
            crate::readers::lone_piece(input, dump.frame_timestep(0), &[]).map(|p| p.note(&p.set))
        }
        Some(_) => None,
    };
    let gzip_cut = dump.gzip_cut().is_some();
    // The working file (if any) lives until the conversion is done.
    convert_dump(dump, input, output, frame, read, options, progress)
        .map(|mut report| {
            report.read_time += opened;
            report.notes.extend(piece);
            report
        })
        .map_err(|e| decompressed(input, text.as_deref(), e))
        .map_err(|e| match e {
            // (A cut last frame of several says which frame converts instead.)
            e if gzip_cut && e.gzip_cut_shows() => ConvertError::GzipCut {
                input: input.to_path_buf(),
                source: Box::new(e),
            },
            e => e,
        })
}

impl ConvertError {
    /// Whether a gzip input's early end explains the error: a frame cut short, or asked
    /// for past the frames before the cut.
    fn gzip_cut_shows(&self) -> bool {
        match self {
            ConvertError::Read(r) => {
                r.cut_short() || matches!(r, crate::readers::ReadError::NoSuchFrame { .. })
            }
            ConvertError::Decompressed { inner, .. } => inner.gzip_cut_shows(),
            _ => false,
        }
    }
}

/// Converts one frame of an opened dump, with `named` (the file the user named) recorded
/// as the source in the metadata.
pub fn convert_dump(
    dump: crate::readers::DumpFile,
    named: &Path,
    output: &Path,
    frame: FrameSelect,
    read: &crate::readers::ReadOptions,
    options: &ConvertOptions,
    progress: &dyn Progress,
) -> Result<ConvertReport, ConvertError> {
    // The metadata records where the species came from.
    let with_column;
    let options = if options.species_column == read.species_column {
        options
    } else {
        with_column = ConvertOptions {
            species_column: read.species_column.clone(),
            ..options.clone()
        };
        &with_column
    };
    let count = dump.frame_count();
    let k = match frame {
        FrameSelect::Index(k) => k,
        FrameSelect::Last => count.saturating_sub(1),
        FrameSelect::FromEnd(n) => match count.checked_sub(n) {
            Some(k) if n > 0 => k,
            _ => {
                return Err(crate::readers::ReadError::NoSuchFrameFromEnd {
                    path: named.to_path_buf(),
                    back: n,
                    count,
                }
                .into())
            }
        },
    };
    // What the input holds that the conversion does not read.
    let mut notes = dump.frame_notes(k, read);
    notes.extend(dump.input_notes());
    // (Of the dump formats that name their per-atom columns: LAMMPS and XYZ.)
    let columned = matches!(
        dump.format(),
        crate::readers::InputFormat::LammpsText
            | crate::readers::InputFormat::LammpsBinary
            | crate::readers::InputFormat::Xyz
    );
    if let Some(info) = dump.frame_info(k).ok().filter(|_| columned) {
        notes.extend(unkept_columns_note(&info.columns, read));
    }
    let which = |mut r: ConvertReport| {
        r.frame = Some((k, count));
        r.notes.extend(notes.iter().cloned());
        r
    };
    // The last frame asked for by default and cut short: say which frame converts.
    let cut_short = |e: crate::readers::ReadError| {
        if matches!(frame, FrameSelect::Last | FrameSelect::FromEnd(1)) && k > 0 && e.cut_short() {
            ConvertError::LastFrameIncomplete {
                frame: k,
                source: e,
            }
        } else {
            e.into()
        }
    };
    let info = dump.frame_info(k).map_err(cut_short)?;
    // Where an error before the frame is read points.
    let frame_place = || FramePlace {
        path: named.display().to_string(),
        frame: Some(k as u64),
        timestep: info.timestep,
    };
    // The last frame asked for and empty: which frame before it holds particles (their
    // headers say, without reading the atoms).
    if info.particles == 0 && matches!(frame, FrameSelect::Last | FrameSelect::FromEnd(1)) {
        let with_particles = (0..k).rev().find_map(|j| {
            dump.frame_info(j)
                .ok()
                .filter(|i| i.particles > 0)
                .map(|i| (j, i.timestep))
        });
        return Err(ConvertError::LastFrameEmpty {
            place: frame_place(),
            with_particles,
        });
    }
    // An override naming none of the species says how this input names them (a name
    // that cannot occur in it: what to write instead).
    // (Renamed species are named as the user chose, not as the input names them.)
    let naming = if options.radii.is_empty() || !options.species_names.is_empty() {
        None
    } else {
        dump.species_naming(k, read).ok()
    };
    let explain = |e: ConvertError| match e {
        ConvertError::Species(s) => {
            ConvertError::Species(Box::new(crate::species::UnknownSpecies {
                input: Some(named.display().to_string()),
                naming: naming.clone(),
                renamed: options.species_names.clone(),
                ..*s
            }))
        }
        ConvertError::UnknownRename(r) => {
            ConvertError::UnknownRename(Box::new(crate::species::UnknownRename {
                input: Some(named.display().to_string()),
                ..*r
            }))
        }
        e => e,
    };
    if info.particles > options.chunks.chunk_points {
        // A column or vector the frame lacks is said as such first (what a frame built
        // whole says), not as a magnitude too large to take.
        dump.attribute_name(k, read).map_err(cut_short)?;
        for extra in &read.extra_attributes {
            dump.attribute_name(k, &read.reading(extra))
                .map_err(cut_short)?;
        }
        // Refused before the frame is read (`convert_frame_with` says why).
        let problem = chunked_magnitude_problem(
            &dump,
            read,
            info.particles as u64,
            options.chunks.chunk_points,
        );
        if let Some(problem) = problem {
            return Err(ConvertError::Attributes {
                place: frame_place(),
                problem,
            });
        }
    }
    if info.particles > options.chunks.chunk_points {
        if let Some(source) = window_source(&dump, k, read, &info) {
            // Out of core: the frame is read a window at a time.
            drop(dump);
            let metadata = base_metadata(
                &header_of(&info),
                Some(crate::batch::fingerprint(named, k as u64)),
                options,
            );
            return convert_chunked(source.as_ref(), metadata, output, options, progress)
                .map(which)
                .map_err(explain);
        }
    }
    if info.particles <= options.chunks.chunk_points {
        check_in_memory(
            info.particles,
            read.extra_attributes.len(),
            options,
            frame_place,
        )?;
    }
    let t0 = Instant::now();
    let frame = dump.read_frame(k, read, progress).map_err(cut_short)?;
    let further = read_extra_attributes(&dump, k, read).map_err(cut_short)?;
    // The frame owns its data: release the mapped (or decompressed) dump before the
    // hierarchy's working memory is allocated.
    drop(dump);
    let read_time = t0.elapsed();
    let mut report = convert_frame_with(
        &frame,
        &further,
        Some(crate::batch::fingerprint(named, k as u64)),
        output,
        options,
        progress,
    )
    .map_err(explain)?;
    report.read_time = read_time;
    Ok(which(report))
}

/// The further attributes `read` asks for (`extra_attributes`), each read from frame `k`
/// of `dump` as its attribute, by a pass over the frame of its own, in the order asked.
pub fn read_extra_attributes(
    dump: &crate::readers::DumpFile,
    k: usize,
    read: &crate::readers::ReadOptions,
) -> Result<Vec<crate::frame::Attribute>, crate::readers::ReadError> {
    read.extra_attributes
        .iter()
        .map(|name| {
            // (A text dump's pass parses that column alone.)
            let one = crate::readers::ReadOptions {
                values_only: true,
                ..read.reading(name)
            };
            let frame = dump.read_frame(k, &one, &crate::progress::NoProgress)?;
            Ok(frame.attribute.unwrap_or(crate::frame::Attribute {
                name: name.clone(),
                values: Vec::new(),
            }))
        })
        .collect()
}

/// Says which of a dump's per-atom columns a conversion that keeps no attribute leaves
/// behind (`c_pe`, `vx`, a CNA's `c_cna`): an OVITO user expects every column, and
/// learns only at render time that none was kept. `None` where an attribute is kept or
/// nothing is left.
pub fn unkept_columns_note(
    columns: &[String],
    read: &crate::readers::ReadOptions,
) -> Option<String> {
    if read.attribute.is_some() || !read.extra_attributes.is_empty() {
        return None;
    }
    // What every conversion reads or what carries no per-atom quantity to show.
    const READ: &[&str] = &[
        "id", "type", "element", "mol", "x", "y", "z", "xs", "ys", "zs", "xu", "yu", "zu", "xsu",
        "ysu", "zsu", "ix", "iy", "iz", "radius", "diameter", "species", "pos", "proc", "procp1",
    ];
    let left: Vec<&str> = columns
        .iter()
        .map(String::as_str)
        .filter(|c| {
            // (An extended XYZ property of several columns names each `pos[0]`, ...)
            let base = c.split_once('[').map_or(*c, |(b, _)| b);
            // (The size column named, `--radius-column h`, is read as every radius.)
            let sized = match &read.sizes {
                crate::readers::SizeColumn::Radius(n) | crate::readers::SizeColumn::Diameter(n) => {
                    n == c
                }
                _ => false,
            };
            !READ.contains(&base.to_ascii_lowercase().as_str())
                && read.species_column.as_deref() != Some(*c)
                && !sized
        })
        .collect();
    if left.is_empty() {
        return None;
    }
    let shown: Vec<&str> = left.iter().take(8).copied().collect();
    Some(format!(
        "the input's column{} {}{} {} not kept: --attribute {} keeps one to colour, light or \
         hide by (repeat it for more)",
        if left.len() == 1 { "" } else { "s" },
        shown.join(", "),
        if left.len() > 8 {
            format!(" and {} more", left.len() - 8)
        } else {
            String::new()
        },
        if left.len() == 1 { "is" } else { "are" },
        left[0]
    ))
}

/// Describes a source file for the metadata.
pub fn source_info(path: &Path, frame: u64) -> SourceInfo {
    let meta = std::fs::metadata(path).ok();
    let modified = meta
        .as_ref()
        .and_then(|m| m.modified().ok())
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
    SourceInfo {
        path: path.display().to_string(),
        size: meta.as_ref().map_or(0, |m| m.len()),
        modified_unix: modified.map(|d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX)),
        modified_nanos: modified.map(|d| d.subsec_nanos()),
        frame,
        bytes: None,
    }
}

#[cfg(test)]
mod tests {
    /// An extended XYZ file's positions (`pos[0]` to `pos[2]`) and sizes are read, so
    /// only its other columns are named as not kept; none, none.
    #[test]
    fn columns_of_several_values_read_are_not_named_unkept() {
        let read = crate::readers::ReadOptions::default();
        let cols = |c: &[&str]| c.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let note = super::unkept_columns_note(
            &cols(&["species", "pos[0]", "pos[1]", "pos[2]", "c_ke", "radius"]),
            &read,
        )
        .unwrap();
        assert!(
            note.starts_with("the input's column c_ke is not kept"),
            "{note}"
        );
        assert_eq!(
            super::unkept_columns_note(&cols(&["species", "pos[0]", "pos[1]", "pos[2]"]), &read),
            None
        );
        // A size column named (an SPH run's smoothing length) is read, not left behind.
        let sized = crate::readers::ReadOptions {
            sizes: crate::readers::SizeColumn::Radius("h".into()),
            ..Default::default()
        };
        assert_eq!(
            super::unkept_columns_note(
                &cols(&["species", "pos[0]", "pos[1]", "pos[2]", "h"]),
                &sized
            ),
            None
        );
    }

    /// Unwrapped coordinates reaching a fifth of a box length past a periodic face are
    /// noted with --wrap; along a fixed axis, or within a tenth, not.
    #[test]
    fn particles_far_outside_a_periodic_box_are_noted() {
        use mdlod_format::meta::SimulationBox;
        let b = |periodic| SimulationBox {
            origin: [0.0; 3],
            a: [10.0, 0.0, 0.0],
            b: [0.0, 10.0, 0.0],
            c: [0.0, 0.0, 10.0],
            periodic,
        };
        let (lo, hi) = ([-2.0, 0.5, 0.5], [9.5, 9.5, 10.5]);
        let note = super::outside_periodic_note(lo, hi, &b(Some([true; 3]))).expect("a note");
        assert!(
            note == "the particles reach outside the periodic box: 0.20 box lengths along x (-2 to 9.5 against the box's 0 to 10): unwrapped coordinates? --wrap wraps them into the cell",
            "{note}"
        );
        assert_eq!(
            super::outside_periodic_note(lo, hi, &b(Some([false, true, true]))),
            None
        );
        assert_eq!(super::outside_periodic_note(lo, hi, &b(None)), None);
    }

    /// Thousands of species are asked about as ids; a protein's `CA` is noted.
    #[test]
    fn most_of_a_frame_outside_its_box_blames_the_box_not_the_run() {
        let species = vec![mdlod_format::meta::Species {
            name: "0".into(),
            radius: 0.5,
            colour: [0.5; 3],
            radius_range: None,
        }];
        let note = |outside: usize| {
            let far = super::FarOutside {
                count: Some(outside),
                beyond: 99.0,
                farthest: None,
            };
            super::position_notes(
                [0.0; 3],
                [100.0; 3],
                1000,
                &species,
                Some(far),
                None,
                None,
                &[],
            )
            .into_iter()
            .find(|n| n.contains("box lengths outside"))
            .unwrap()
        };
        assert!(note(3).contains("lost atoms of a run that blew up?"));
        // A box of no width along an axis the particles spread along is noted; one they
        // lie flat in (a two-dimensional run) is not.
        let flat =
            mdlod_format::meta::SimulationBox::orthogonal([5.0, 0.0, 0.0], [5.0, 10.0, 10.0]);
        let spread = |lo: f32, hi: f32| {
            super::position_notes(
                [lo, 0.0, 0.0],
                [hi, 10.0, 10.0],
                1000,
                &species,
                None,
                Some(&flat),
                None,
                &[],
            )
            .into_iter()
            .find(|n| n.contains("no width"))
        };
        assert!(spread(0.0, 23.0).is_some_and(|n| n.contains("x from 0 to 23")));
        assert!(spread(5.0, 5.0).is_none());
        // A box past single precision's range is noted.
        let huge = mdlod_format::meta::SimulationBox::orthogonal([0.0; 3], [1e39, 10.0, 10.0]);
        let notes = super::position_notes(
            [0.0; 3],
            [10.0; 3],
            1000,
            &species,
            None,
            Some(&huge),
            None,
            &[],
        );
        assert!(
            notes
                .iter()
                .any(|n| n.starts_with("the box reaches 1.000e39")),
            "{notes:?}"
        );
        let fine = mdlod_format::meta::SimulationBox::orthogonal([0.0; 3], [10.0; 3]);
        let notes = super::position_notes(
            [0.0; 3],
            [10.0; 3],
            1000,
            &species,
            None,
            Some(&fine),
            None,
            &[],
        );
        assert!(
            !notes.iter().any(|n| n.contains("the box reaches")),
            "{notes:?}"
        );
        let most = note(900);
        assert!(
            most.contains("is the box the file records not the data's")
                && !most.contains("blew up"),
            "{most}"
        );
    }

    #[test]
    fn ids_read_as_species_and_atom_names_read_as_elements_are_noted() {
        let species = |names: Vec<String>| -> Vec<mdlod_format::meta::Species> {
            names
                .into_iter()
                .map(|name| mdlod_format::meta::Species {
                    name,
                    radius: 0.5,
                    colour: [0.5; 3],
                    radius_range: None,
                })
                .collect()
        };
        let ids = species((1..=1200).map(|i| i.to_string()).collect());
        let notes = super::position_notes([0.0; 3], [100.0; 3], 5000, &ids, None, None, None, &[]);
        assert!(
            notes
                .iter()
                .any(|n| n
                    .starts_with("1200 species (1, 2, ...): a molecule, residue or cluster id")),
            "{notes:?}"
        );
        let protein = species(vec!["N".into(), "CA".into(), "C".into(), "O".into()]);
        let notes =
            super::position_notes([0.0; 3], [100.0; 3], 5000, &protein, None, None, None, &[]);
        assert!(
            notes.len() == 1 && notes[0].contains("--species-name CA=C"),
            "{notes:?}"
        );
    }

    /// Type numbers left at the default radius in coarse-grained data (beads five apart)
    /// are noted as dots, with a radius of half the spacing; atoms two or three apart,
    /// elements, and species given a radius are not.
    #[test]
    fn default_radii_far_below_the_spacing_are_noted() {
        let species = |names: &[&str], radius: f32| -> Vec<mdlod_format::meta::Species> {
            names
                .iter()
                .map(|n| mdlod_format::meta::Species {
                    name: n.to_string(),
                    radius,
                    colour: [0.5; 3],
                    radius_range: None,
                })
                .collect()
        };
        let default = crate::species::DEFAULT_RADIUS;
        // 8000 beads in a 100³ box: 5 apart.
        let beads = species(&["1", "2", "PO4"], default);
        let note = super::undersized_note([0.0; 3], [100.0; 3], 8000, &beads, &[]).expect("a note");
        assert!(
            note.starts_with(
                "species 1, 2, PO4: drawn at the default radius 0.5, 0.10 of the particles' \
                 mean spacing (5.000"
            ) && note.contains("--radius 1=R, about half the spacing (2.5)"),
            "{note}"
        );
        assert!(
            super::position_notes([0.0; 3], [100.0; 3], 8000, &beads, None, None, None, &[])
                .iter()
                .any(|n| n == &note)
        );
        // 2.5 apart, as atoms in metal units: drawn as they are.
        assert_eq!(
            super::undersized_note([0.0; 3], [100.0; 3], 64_000, &beads, &[]),
            None
        );
        // Elements keep their radii; a radius given is the user's.
        let elements = species(&["Na", "Cl"], default);
        assert_eq!(
            super::undersized_note([0.0; 3], [100.0; 3], 8000, &elements, &[]),
            None
        );
        let given = species(&["1"], 0.6);
        assert_eq!(
            super::undersized_note([0.0; 3], [100.0; 3], 8000, &given, &[]),
            None
        );
        // Given, even at the default's value (`--radius 1=0.5`).
        assert_eq!(
            super::undersized_note(
                [0.0; 3],
                [100.0; 3],
                8000,
                &beads,
                &[("1".into(), 0.5), ("2".into(), 0.5), ("PO4".into(), 0.5)]
            ),
            None
        );
        // A flat sheet: its spacing over the area it spans; so for a sheet relaxed a
        // little off its plane (±0.001 over 100 units), which spanned 0.12 over its
        // volume.
        let sheet = super::undersized_note([0.0; 3], [100.0, 100.0, 0.0], 400, &beads, &[]);
        assert!(sheet.is_some_and(|n| n.contains("spacing (5.000")));
        let relaxed =
            super::undersized_note([0.0, 0.0, -0.001], [100.0, 100.0, 0.001], 400, &beads, &[]);
        assert!(relaxed.is_some_and(|n| n.contains("spacing (5.000")));
        // A slab thicker than its spacing is three-dimensional.
        assert_eq!(
            super::mean_spacing([0.0; 3], [100.0, 100.0, 10.0], 800_000),
            Some(0.5)
        );
        // A line of beads in a thin tube: its length per bead.
        assert_eq!(
            super::mean_spacing([0.0; 3], [100.0, 0.01, 0.01], 100),
            Some(1.0)
        );
    }

    /// Ids past 65 536 apart are noted as ids that 16 bits cannot tell apart, ids past
    /// 32 768 apart as ids whose halfway ends are unsafe; whole numbers closer together,
    /// or values with fractions, are not.
    #[test]
    fn whole_numbers_too_many_for_16_bits_are_noted() {
        let ids: Vec<f32> = (1..=200_000).map(|i| i as f32).collect();
        let note = super::whole_numbers_note("mol", &ids, 1.0, 200_000.0)
            .flatten()
            .expect("a note");
        assert!(
            note.starts_with("attribute mol holds whole numbers from 1 to 200000 (ids?)")
                && note.contains("(a step is 3.05)"),
            "{note}"
        );
        assert_eq!(
            super::whole_numbers_note("mol", &ids[..30_000], 1.0, 30_000.0),
            Some(None)
        );
        // Steps above a half: ends halfway between ids are said to be unsafe. With a
        // step of 0.92, 300 and 300.5 share a step (its end's code holds the 300s).
        let note = super::whole_numbers_note("mol", &ids[..60_000], 1.0, 60_000.0)
            .flatten()
            .expect("a note");
        assert!(
            note.contains("each in a 16-bit step of its own (a step is 0.92)")
                && note.contains("give whole-number ends (300:300)"),
            "{note}"
        );
        let info = mdlod_format::meta::AttributeInfo {
            name: "mol".into(),
            min: 1.0,
            max: 60_000.0,
            log10: false,
        };
        let (_, below) = info.codes([f32::NEG_INFINITY, 299.5]).unwrap();
        let (above, _) = info.codes([300.5, f32::INFINITY]).unwrap();
        let q = info.encode(300.0);
        assert!(
            q <= below || q >= above,
            "300 ({q}) kept by {below}..{above}"
        );
        let mut fractions = ids.clone();
        fractions[7] = 7.5;
        assert_eq!(
            super::whole_numbers_note("x", &fractions, 1.0, 200_000.0),
            None
        );
    }

    /// 8-bit positions off by more than a twentieth of the smallest radius say so;
    /// 16-bit ones, and 8-bit ones within it, say nothing.
    #[test]
    fn coarse_positions_are_noted_against_the_smallest_radius() {
        let species = |r: f32| {
            vec![mdlod_format::meta::Species {
                name: "1".into(),
                radius: r,
                colour: [1.0; 3],
                radius_range: Some([r / 2.0, r * 2.0]),
            }]
        };
        let note = super::precision_note(4.4e-5, 8, &species(1e-3)).expect("a note");
        assert_eq!(
            note,
            "8-bit positions are off by up to 4.40e-5, 9 % of the smallest particle's radius \
             (0.0005): --precision u16, the default, places them 256 times closer"
        );
        assert_eq!(super::precision_note(4.4e-5, 16, &species(1e-3)), None);
        assert_eq!(super::precision_note(2e-5, 8, &species(1e-3)), None);
    }

    /// A contact force's spike among forces of a few hundredths puts them in one 16-bit
    /// step: said, with the bounds of the middle 98 %, which hold the true percentiles;
    /// the same forces without it, a Gaussian's tails, and too few values to set a
    /// hundredth aside say nothing. Counted window by window, the octaves are the same.
    #[test]
    fn a_few_far_values_stretching_a_range_are_noted() {
        // Deterministic values in [-0.02, 0.02).
        let mut x = 12345u64;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 40) as f64 / (1u64 << 24) as f64
        };
        let mut forces: Vec<f32> = (0..5000).map(|_| (0.04 * next() - 0.02) as f32).collect();
        let (lo, hi) = super::Octaves::of(&forces).bulk().unwrap();
        let mut sorted = forces.clone();
        sorted.sort_by(f32::total_cmp);
        assert!(lo <= f64::from(sorted[50]) && f64::from(sorted[4949]) <= hi);
        assert!(lo >= -0.04 && hi <= 0.04, "{lo} {hi}");
        assert_eq!(
            super::bulk_note("fz", -0.02, 0.02, &super::Octaves::of(&forces)),
            None
        );
        forces[7] = -2000.0;
        let whole = super::Octaves::of(&forces);
        let mut windows = super::Octaves::default();
        for w in forces.chunks(777) {
            windows.add(&super::Octaves::of(w));
        }
        assert_eq!(windows, whole);
        let note = super::bulk_note("fz", -2000.0, 0.02, &whole).expect("a note");
        assert!(
            note.starts_with(
                "attribute fz: 98 % of its values lie between -3.125e-2 and 2e-2, within 2 of \
                 the 65 535 16-bit steps of its range -2e3 to 2e-2"
            ) && note.contains("`variable c atom max(min(fz,2e-2),-3.125e-2)`"),
            "{note}"
        );
        // A Gaussian's 5000 values reach about 3.7 of its widths: no far values.
        let gauss: Vec<f32> = (0..5000)
            .map(|_| {
                let (u, v) = (next().max(1e-12), next());
                ((-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
            })
            .collect();
        let (min, max) = super::par_min_max(&gauss);
        assert_eq!(
            super::bulk_note("vx", min, max, &super::Octaves::of(&gauss)),
            None
        );
        assert_eq!(super::Octaves::of(&forces[..99]).bulk(), None);
    }

    /// A kinetic energy with walls at rest: most grains' values far below a step are
    /// said; a column whose small values are few, or all above 0, is not.
    #[test]
    fn values_below_a_step_of_a_range_from_zero_are_noted() {
        let mut ke = vec![0.0f32; 100];
        ke.extend((0..100).map(|i| 10f32.powi(-(i % 30)) * 4.46));
        let note = super::below_step_note("c_ke", &ke, 0.0, 4.46).expect("a note");
        assert!(
            note.starts_with("attribute c_ke: 80 of the 100 values above 0 lie below one 16-bit step (6.81e-5) of its range 0 to 4.46")
                && note.contains("the smallest is 4.46e-29"),
            "{note}"
        );
        let few: Vec<f32> = (0..1000)
            .map(|i| if i == 0 { 1e-9 } else { i as f32 })
            .collect();
        assert_eq!(super::below_step_note("v", &few, 0.0, 999.0), None);
        assert_eq!(
            super::below_step_note("v", &ke[100..], 4.46e-29, 4.46),
            None
        );
    }

    use super::*;

    /// Column densities spanning ten decades, each particle's area its h² (mass = Σ
    /// σ·h²): the 16-bit steps lose most of the mass held by the many faint particles;
    /// a narrow range loses nothing worth saying.
    #[test]
    fn the_attribute_total_lost_to_16_bit_steps_is_measured() {
        // h from 10 down to 1e-4 (log-spaced), σ = m / h² with equal masses.
        let n = 10_000;
        let h: Vec<f64> = (0..n)
            .map(|i| 10f64.powf(1.0 - 5.0 * i as f64 / n as f64))
            .collect();
        let sigma: Vec<f32> = h.iter().map(|h| (1.0 / (h * h)) as f32).collect();
        let (min, max) = (sigma[0], sigma[n - 1]);
        let lost = super::quantized_total_loss(&sigma, |i| h[i] * h[i], min, max).unwrap();
        assert!(lost > 0.3, "{lost}");
        // The same values within one decade: kept to within rounding.
        let narrow: Vec<f32> = (0..n).map(|i| 1.0 + 9.0 * i as f32 / n as f32).collect();
        assert_eq!(
            super::quantized_total_loss(&narrow, |_| 1.0, 1.0, 10.0),
            None
        );
    }

    /// Radii many spacings wide are named (nanometre data in metres with angström
    /// radii), in 3D, 2D and on a line; radii about the spacing are not.
    #[test]
    fn radii_far_wider_than_the_spacing_are_noted() {
        let species = |r: &[f32]| -> Vec<mdlod_format::meta::Species> {
            r.iter()
                .enumerate()
                .map(|(i, &radius)| mdlod_format::meta::Species {
                    name: format!("S{i}"),
                    radius,
                    colour: [0.5; 3],
                    radius_range: None,
                })
                .collect()
        };
        // 1000 particles in a 5 nm cube (spacing 0.5 nm), argon's 1.92.
        let note = oversized_note([0.0; 3], [5e-9; 3], 1000, &species(&[1.92]), None).unwrap();
        assert!(
            note.contains(
                "the radius of S0 (1.92) is 3.8e9 times the mean spacing of those particles"
            ),
            "{note}"
        );
        // Water in nm (spacing 0.22 nm) with oxygen's 0.74 Å: 3.4 spacings; in Å, none.
        let water = 0.22 * 1000f32.cbrt();
        let note = oversized_note([0.0; 3], [water; 3], 1000, &species(&[0.74]), None).unwrap();
        assert!(
            note.contains("(0.74) is 3.4 times the mean spacing of those particles (0.2200,"),
            "{note}"
        );
        assert_eq!(
            oversized_note([0.0; 3], [10.0 * water; 3], 1000, &species(&[0.74]), None),
            None
        );
        // A copper crystal (spacing 2.28 Å) at 1.28; a 2D layer at 0.5 and spacing 1.1.
        let cube = 2.28 * 1000f32.cbrt();
        assert_eq!(
            oversized_note([0.0; 3], [cube; 3], 1000, &species(&[1.28]), None),
            None
        );
        let (lo, hi) = ([0.0, 0.0, 0.0], [44.0, 27.5, 0.0]);
        assert_eq!(
            oversized_note(lo, hi, 1000, &species(&[0.5, 0.5]), None),
            None
        );
        // The same layer in metres: its second species named too.
        let (lo, hi) = ([0.0, 0.0, 0.0], [44e-9, 27.5e-9, 0.0]);
        let note = oversized_note(lo, hi, 1000, &species(&[0.5, 0.7]), None).unwrap();
        assert!(
            note.contains("the radii of S0 (0.5), S1 (0.7) are up to"),
            "{note}"
        );
        // Two particles 1 Å apart: one blob at 1.9 only when the data is in metres.
        let (lo, hi) = ([0.0; 3], [1e-10, 0.0, 0.0]);
        assert!(oversized_note(lo, hi, 2, &species(&[1.9]), None).is_some());
        let (lo, hi) = ([0.0; 3], [3.0, 0.0, 0.0]);
        assert_eq!(oversized_note(lo, hi, 2, &species(&[1.9]), None), None);
        // One particle, or all in one place: no spacing to compare with.
        assert_eq!(
            oversized_note([1.0; 3], [1.0; 3], 1, &species(&[1.9]), None),
            None
        );
        assert_eq!(
            oversized_note([1.0; 3], [1.0; 3], 50, &species(&[1.9]), None),
            None
        );
        // A granular bed of spacing 1 with one intruder of radius 5: it overlaps nothing
        // (its own particles' spacing is the whole box). A thousand of them would.
        let side = 6400f32.cbrt();
        let bed = species(&[0.5, 5.0]);
        assert!(oversized_note([0.0; 3], [side; 3], 6401, &bed, None).is_some());
        assert_eq!(
            oversized_note([0.0; 3], [side; 3], 6401, &bed, Some(&[6400, 1])),
            None
        );
        let note = oversized_note([0.0; 3], [side; 3], 7400, &bed, Some(&[6400, 1000])).unwrap();
        assert!(note.contains("the radius of S1 (5) is"), "{note}");
    }

    /// The hint names chunks that fit the limit (after the chunk's fixed working memory),
    /// rounded down to two digits, and only where such chunks are smaller than the frame
    /// and hold at least the root points.
    #[test]
    fn the_memory_hint_names_chunks_that_fit_the_limit() {
        let limit = 100u64 << 20;
        let hint = chunk_hint(1_000_000, limit, 4096, 0);
        let fits =
            (limit - crate::chunked::chunk_memory(0)) / crate::chunked::BUILD_BYTES_PER_PARTICLE;
        assert_eq!(fits, 343_170);
        assert_eq!(
            hint,
            ", or build it out of core in smaller chunks (--chunk-points 340000)"
        );
        assert!(crate::chunked::chunk_memory(340_000) <= limit);
        // Room for fewer than the root points, or for the whole frame: no hint.
        assert_eq!(chunk_hint(1_000_000, 64 << 20, 4096, 0), "");
        assert_eq!(chunk_hint(100_000, limit, 4096, 0), "");
        // The build's own root points: no chunk below them is suggested.
        assert_eq!(chunk_hint(1_000_000, limit, 500_000, 0), "");
        let just = crate::chunked::chunk_memory(4099);
        assert!(chunk_hint(1_000_000, just, 4096, 0).ends_with("(--chunk-points 4096)"));
        let options = ConvertOptions {
            chunks: crate::chunked::ChunkOptions {
                memory_limit: limit,
                ..Default::default()
            },
            ..Default::default()
        };
        let place = || FramePlace::of(None, Some(7));
        check_in_memory(700_000, 0, &options, place).unwrap();
        let e = check_in_memory(1_000_000, 0, &options, place)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "input: timestep 7: 1000000 particles are built in memory (within --chunk-points \
             4194304) and need about 134 MiB, above the memory limit of 100 MiB: raise \
             --memory-limit, or build it out of core in smaller chunks (--chunk-points 340000)"
        );
        // Further attributes need more, built whole or in chunks: the chunks suggested
        // fit the limit with them.
        let e = check_in_memory(700_000, 3, &options, place)
            .unwrap_err()
            .to_string();
        let points: usize = e
            .rsplit("--chunk-points ")
            .next()
            .and_then(|t| t.trim_end_matches(')').parse().ok())
            .unwrap_or_else(|| panic!("{e}"));
        assert!(points < 340_000, "{e}");
        assert!(crate::chunked::chunk_memory_with(points, 3) <= limit, "{e}");
    }
}
