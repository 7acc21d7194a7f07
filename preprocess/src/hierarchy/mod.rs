//! The level-of-detail hierarchy (Hopf et al. 2003, sections 3-5).
//!
//! How it works:
//! 1. The particles are the finest level. [`pca_split::cluster`] splits them into
//!    clusters of at most `max_cluster_size` points by PCA splits.
//! 2. Each cluster gets a representative point ([`representative`]): the radius-weighted
//!    centroid, a radius from Eq. 2, and the same radiant flux as its members (Eq. 1:
//!    the area Σ r² and the area-weighted colour are kept). The representatives form the
//!    next coarser level, which is split again, until a level has at most
//!    `max_root_points`; a single top node above it closes the hierarchy.
//! 3. The levels are put in their final order top-down: the children of every node are
//!    contiguous and in the order of their parents, so every node's descendants on any
//!    deeper level form one range (one draw call).
//! 4. Every point of level `m ≥ 1` is quantized relative to its ancestor on level
//!    `max(0, m − δn)` ([`mdlod_format::quantize`]); the largest decoding error over all
//!    particles is measured and recorded.
//!
//! Every step is deterministic and independent of the thread count: parallel work only
//! ever splits independent clusters or maps over independent items, and each sum is
//! accumulated in a fixed order.

pub mod extra;
pub mod pca_split;
pub mod representative;

use std::ops::Range;
use std::path::Path;

use mdlod_format::layout::{LevelRecord, NodeRecord, SectionKind};
use mdlod_format::meta::{AttributeInfo, Metadata, Species};
use mdlod_format::{quantize, FormatError, Writer};
use rayon::prelude::*;

use crate::progress::{NoProgress, Progress};
use pca_split::{cluster, Clusters, Item};
use representative::{LevelPoints, Source};

/// How to build the hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildParams {
    /// A cluster is split while it holds more than this many points (≥ 2).
    pub max_cluster_size: u32,
    /// The coarsest real level holds at most this many points.
    pub max_root_points: u32,
    /// A node encodes (and is drawn with) its descendants `delta_n` levels down.
    pub delta_n: u32,
    /// Bits per quantized coordinate: 8 or 16.
    pub position_bits: u32,
}

impl Default for BuildParams {
    fn default() -> Self {
        BuildParams {
            max_cluster_size: 8,
            max_root_points: 4096,
            delta_n: 1,
            position_bits: 16,
        }
    }
}

/// Refuses a level table whose nodes (every level but the last) are more than 32-bit
/// indices number: `parent` and `quant_node` would wrap, and every reader refuses such a
/// file (FORMAT.md, section 4) — better said before the file is written.
pub fn check_node_total(levels: &[LevelRecord]) -> Result<(), BuildError> {
    let nodes = levels
        .iter()
        .take(levels.len().saturating_sub(1))
        .fold(0u64, |sum, l| sum.saturating_add(l.point_count));
    if nodes > u64::from(u32::MAX) {
        return Err(BuildError::TooManyNodes(nodes));
    }
    Ok(())
}

/// Forwards half of the amounts it is given, exactly in sum (`⌊total / 2⌋` once all
/// are given, whatever the order and threads they come from).
struct Halved<'a> {
    inner: &'a dyn Progress,
    given: std::sync::atomic::AtomicU64,
}

impl Progress for Halved<'_> {
    fn stage(&self, name: &str, total: Option<u64>, unit: &'static str) {
        self.inner.stage(name, total, unit);
    }

    fn advance(&self, amount: u64) {
        let before = self
            .given
            .fetch_add(amount, std::sync::atomic::Ordering::Relaxed);
        self.inner
            .advance(before.saturating_add(amount) / 2 - before / 2);
    }

    fn finish_stage(&self) {
        self.inner.finish_stage();
    }
}

/// Errors of building a hierarchy.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("invalid build parameters: {0}")]
    Params(String),
    #[error("no particles to build a hierarchy from")]
    Empty,
    #[error("{0} particles: a level holds at most 4294967295 points in format version 1")]
    TooMany(usize),
    #[error("{0} nodes in all: format version 1 numbers nodes in 32 bits (at most 4294967295); build with a larger cluster size")]
    TooManyNodes(u64),
    #[error("particle {index} has a non-finite position {position:?}")]
    NonFinite { index: usize, position: [f32; 3] },
    #[error("{0} species: a file holds at most {MAX_SPECIES}")]
    TooManySpecies(usize),
    #[error("particle {index} has radius {radius} (a particle's radius must be a finite number from 0 up)")]
    BadRadius { index: usize, radius: f32 },
    #[error("particle {index}: radius {radius:e}: the frame's {particles} particles at that radius would add up to squared radii of {sum:.2e}, beyond the {MAX_AREA_SUM:e} single precision holds (a bound over the whole frame, as the top node sums every particle); convert it in larger length units")]
    ParticleRadiusTooLarge {
        index: usize,
        radius: f32,
        particles: usize,
        sum: f64,
    },
    #[error("particle {index} has a non-finite attribute value {value}")]
    NonFiniteAttribute { index: usize, value: f32 },
    #[error("attribute {name}: particle {index} has the value {value}: its logarithm (--attribute-log10) needs values above 0")]
    NotPositiveAttribute {
        name: String,
        index: usize,
        value: f32,
    },
    #[error("particle {index} at {position:?} lies beyond ±{MAX_COORDINATE:e}, where differences of single-precision coordinates overflow; convert it in larger length units")]
    OutOfRange { index: usize, position: [f32; 3] },
    #[error("species `{name}`: radius {radius:e}: the frame's {particles} particles at that radius would add up to squared radii of {sum:.2e}, beyond the {MAX_AREA_SUM:e} single precision holds (a bound over the whole frame, as the top node sums every particle); convert it in larger length units")]
    RadiusTooLarge {
        name: String,
        radius: f32,
        particles: usize,
        sum: f64,
    },
    #[error("particle {index} has species index {species} but only {count} species are defined")]
    BadSpecies {
        index: usize,
        species: u16,
        count: usize,
    },
}

/// The particles to build from, borrowed from a [`crate::Frame`] or any other source.
#[derive(Clone, Copy, Debug)]
pub struct Particles<'a> {
    pub positions: &'a [[f32; 3]],
    pub species_index: &'a [u16],
    pub species: &'a [Species],
    pub attribute: Option<&'a [f32]>,
    /// Each particle's own radius, where the file keeps them ([`particle_radii`]); the
    /// species' radius otherwise.
    pub radii: Option<&'a [f32]>,
}

/// Each particle's radius as a file with per-particle radii keeps it, or `None` where the
/// file keeps none: where no species of `species` (the file's table, overrides applied)
/// is of several sizes, or the input gives no sizes. A particle of such a species takes
/// its own size from `radii`; any other its species' radius.
pub fn particle_radii(
    species: &[Species],
    species_index: &[u16],
    radii: Option<&[f32]>,
) -> Option<Vec<f32>> {
    let radii = radii?;
    if !species.iter().any(|s| s.radius_range.is_some()) {
        return None;
    }
    Some(
        species_index
            .par_iter()
            .zip(radii)
            .map(|(&s, &r)| match species.get(usize::from(s)) {
                Some(sp) if sp.radius_range.is_none() => sp.radius,
                _ => r,
            })
            .collect(),
    )
}

/// The range the radii of [`particle_radii`] are quantized over, from the species table
/// and each species' particle count alone (so every chunk of a frame takes the same, and
/// a whole build the same as its particles' smallest and largest radius): the smallest
/// and largest of the radius ranges of the species of several sizes and the radii of
/// the others, of the species with particles. `None` where no species is of several
/// sizes.
pub fn radius_range(species: &[Species], counts: &[u64]) -> Option<mdlod_format::meta::RadiusInfo> {
    species.iter().find(|s| s.radius_range.is_some())?;
    let (min, max) = species.iter().zip(counts).filter(|(_, &n)| n > 0).fold(
        (f32::INFINITY, 0.0f32),
        |(lo, hi), (s, _)| {
            let [a, b] = s.radius_range.unwrap_or([s.radius; 2]);
            (lo.min(a), hi.max(b))
        },
    );
    (min <= max).then(|| mdlod_format::meta::RadiusInfo::for_range(min, max))
}

/// A built hierarchy, in final order, ready to be written.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    pub params: BuildParams,
    pub levels: Vec<LevelRecord>,
    pub nodes: Vec<NodeRecord>,
    /// Quantized positions of levels 1.. (index 0 is empty).
    pub quantized: Vec<Vec<[u16; 3]>>,
    /// Input index of every particle in final order.
    pub particle_order: Vec<u32>,
    /// Species index per particle, final order.
    pub species_index: Vec<u16>,
    /// Quantized attribute per particle, final order, with its range.
    pub attribute: Option<(Vec<u16>, f32, f32)>,
    /// Quantized radius per particle, final order, with its range.
    pub radius: Option<(Vec<u16>, mdlod_format::meta::RadiusInfo)>,
    /// Further attributes ([`extra::extra_attributes`]), written after the first.
    pub extra_attributes: Vec<extra::ExtraAttribute>,
    /// Largest distance between a decoded particle and its input position.
    pub max_position_error: f64,
    /// The top node's representative, at full precision.
    pub root: representative::Rep,
    /// Unquantized positions of levels `0..keep_levels` in final order (see
    /// [`BuildExtras::keep_levels`]); empty by default.
    pub top_positions: Vec<Vec<[f32; 3]>>,
}

/// Options of [`build_with`] that a chunked build needs and a plain build does not.
#[derive(Clone, Debug, Default)]
pub struct BuildExtras {
    /// Quantize the attribute over this range instead of the particles' own.
    pub attribute_range: Option<(f32, f32)>,
    /// Keep the unquantized positions of this many levels from the top.
    pub keep_levels: usize,
    /// Quantize the per-particle radii over this range instead of their own.
    pub radius_range: Option<mdlod_format::meta::RadiusInfo>,
    /// The attribute (positive values, given as they are) is stored as its base-10
    /// logarithm: each particle's, and each node's as the logarithm of its area-weighted
    /// mean value (the metadata's `attribute_log10`); `attribute_range` is then of the
    /// logarithms.
    pub attribute_log10: bool,
}

impl Hierarchy {
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    pub fn particle_count(&self) -> usize {
        self.particle_order.len()
    }

    /// Writes the hierarchy with `metadata` (whose `particles`, `build`,
    /// `max_position_error` and `attribute` range are filled in here).
    pub fn write(&self, path: &Path, mut metadata: Metadata) -> Result<(), FormatError> {
        let last = self.level_count() - 1;
        metadata.particles = self.particle_count() as u64;
        metadata.max_position_error = self.max_position_error;
        metadata.build = mdlod_format::meta::BuildInfo {
            max_cluster_size: self.params.max_cluster_size,
            max_root_points: self.params.max_root_points,
            // δn past the levels below the top changes nothing (every point level and
            // encoding ancestor is clamped to the hierarchy): the file records the δn in
            // effect, which readers require to be at most L − 1.
            delta_n: self.params.delta_n.min(last as u32),
            position_bits: self.params.position_bits,
            chunk_points: metadata.build.chunk_points,
        };
        match (&self.attribute, &mut metadata.attribute) {
            (Some((_, min, max)), Some(info)) => {
                info.min = *min;
                info.max = *max;
            }
            (Some((_, min, max)), None) => {
                metadata.attribute = Some(AttributeInfo {
                    name: "attribute".into(),
                    min: *min,
                    max: *max,
                    log10: false,
                })
            }
            (None, _) => {
                metadata.attribute = None;
                metadata.attribute_log10 = false;
            }
        }
        metadata.radius = self.radius.as_ref().map(|(_, info)| *info);
        metadata.attributes = self
            .extra_attributes
            .iter()
            .map(|e| e.info.clone())
            .collect();
        let json = metadata.to_json().map_err(|problem| FormatError::Write {
            path: path.to_path_buf(),
            problem,
        })?;
        let mut w = Writer::create(path, self.params.position_bits)?;
        w.write_section(SectionKind::Metadata, 0, &json)?;
        w.write_pod_section(SectionKind::Levels, 0, &self.levels)?;
        w.write_pod_section(SectionKind::Nodes, 0, &self.nodes)?;
        for (m, q) in self.quantized.iter().enumerate().skip(1) {
            let mut s = w.section(SectionKind::Positions, m as u32)?;
            if self.params.position_bits == 16 {
                s.write_pod(q)?;
            } else {
                for chunk in q.chunks(1 << 16) {
                    let bytes: Vec<[u8; 3]> = chunk.iter().map(|p| p.map(|v| v as u8)).collect();
                    s.write_pod(&bytes)?;
                }
            }
            s.end()?;
        }
        w.write_pod_section(SectionKind::Species, last as u32, &self.species_index)?;
        if let Some((a, _, _)) = &self.attribute {
            w.write_pod_section(SectionKind::Attribute, last as u32, a)?;
        }
        if let Some((r, info)) = &self.radius {
            let kind = if info.log {
                SectionKind::RadiusLog
            } else {
                SectionKind::Radius
            };
            w.write_pod_section(kind, last as u32, r)?;
        }
        if !self.extra_attributes.is_empty() {
            let mut s = w.section(SectionKind::Attributes, last as u32)?;
            for e in &self.extra_attributes {
                s.write_pod(&e.values)?;
            }
            s.end()?;
            let mut s = w.section(SectionKind::NodeAttributes, 0)?;
            for e in &self.extra_attributes {
                s.write_pod(&e.node_means)?;
            }
            s.end()?;
        }
        w.finish()
    }
}

/// Builds the hierarchy of `particles`.
pub fn build(
    particles: Particles<'_>,
    params: &BuildParams,
    progress: &dyn Progress,
) -> Result<Hierarchy, BuildError> {
    build_with(particles, params, &BuildExtras::default(), progress)
}

/// [`build`] with the options of a chunked build.
pub fn build_with(
    particles: Particles<'_>,
    params: &BuildParams,
    extras: &BuildExtras,
    progress: &dyn Progress,
) -> Result<Hierarchy, BuildError> {
    validate(&particles, params)?;
    let n = particles.positions.len();
    // Per-particle radii are built from as readers decode them, so that every node's
    // bounds and sizes hold the spheres drawn.
    let radius_info = particles.radii.map(|r| {
        extras.radius_range.unwrap_or_else(|| {
            let (min, max) = r.iter().fold((f32::INFINITY, 0.0f32), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
            mdlod_format::meta::RadiusInfo::for_range(min, max)
        })
    });
    let radius_q: Option<Vec<u16>> = particles
        .radii
        .zip(radius_info)
        .map(|(r, info)| r.par_iter().map(|&v| info.encode(v)).collect());
    let decoded: Option<Vec<f32>> = radius_q
        .as_ref()
        .zip(radius_info)
        .map(|(q, info)| q.par_iter().map(|&q| info.decode(q)).collect());
    let particles = Particles {
        radii: decoded.as_deref(),
        ..particles
    };
    // Progress in particles: the finest clustering counts for one pass over them, the
    // rest of the build for another, each reported at half weight (the bar showed
    // 3,000,000 particles for a frame of 1,500,000).
    progress.stage("building hierarchy", Some(n as u64), "particles");
    let halved = Halved {
        inner: progress,
        given: std::sync::atomic::AtomicU64::new(0),
    };
    let progress: &dyn Progress = &halved;

    // 1-2. Cluster level by level, finest first, until the top node.
    let mut clusterings: Vec<Clusters> = Vec::new(); // finest first
    let mut coarser: Vec<LevelPoints> = Vec::new(); // representatives, finest-but-one first
    loop {
        let src = match coarser.last() {
            None => Source::Particles(&particles),
            Some(l) => Source::Reps(l),
        };
        let count = src.len();
        let clusters = if count <= params.max_root_points as usize {
            Clusters {
                order: (0..count as u32).collect(),
                offsets: vec![0, count as u32],
            }
        } else {
            let items: Vec<Item> = (0..count)
                .into_par_iter()
                .map(|i| Item {
                    position: src.position(i),
                    weight: src.radius(i),
                    id: i as u32,
                })
                .collect();
            let p: &dyn Progress = if coarser.is_empty() {
                progress
            } else {
                &NoProgress
            };
            cluster(items, params.max_cluster_size as usize, p)
        };
        let reps = representative::representatives(&src, &clusters);
        if coarser.is_empty() {
            if clusters.len() == 1 {
                progress.advance(n as u64);
            }
            progress.advance(n as u64 / 4);
        }
        let done = clusters.len() == 1;
        clusterings.push(clusters);
        coarser.push(reps);
        if done {
            break;
        }
    }
    let level_count = clusterings.len() + 1;
    let last = level_count - 1;
    // Level l (0 = top) in build order: coarser[last - 1 - l] for l < last.
    let level_src = |l: usize| -> Source<'_> {
        if l == last {
            Source::Particles(&particles)
        } else {
            Source::Reps(&coarser[last - 1 - l])
        }
    };
    // Clusters whose representatives form level l-1 split the points of level l.
    let clusters_of = |l: usize| &clusterings[last - l];

    // 3. Final order, top-down.
    let mut order: Vec<Vec<u32>> = vec![vec![0]];
    let mut child_ranges: Vec<Vec<Range<u32>>> = Vec::new(); // per level < last
    for l in 1..level_count {
        let parents = &order[l - 1];
        let cl = clusters_of(l);
        let mut ranges = Vec::with_capacity(parents.len());
        let mut next = Vec::with_capacity(cl.order.len());
        for &b in parents {
            let start = next.len() as u32;
            next.extend_from_slice(cl.members(b as usize));
            ranges.push(start..next.len() as u32);
        }
        child_ranges.push(ranges);
        order.push(next);
    }

    // Level table.
    let mut levels = Vec::with_capacity(level_count);
    let mut node_first = 0u64;
    for ord in &order {
        levels.push(LevelRecord {
            point_count: ord.len() as u64,
            node_first,
            reserved: [0; 2],
        });
        node_first += ord.len() as u64;
    }
    levels[last].node_first = levels[last - 1].node_first + levels[last - 1].point_count;
    check_node_total(&levels)?;

    progress.advance(n as u64 / 4);
    // 4. Nodes.
    let delta_n = params.delta_n as usize;
    let mut nodes: Vec<NodeRecord> = Vec::with_capacity(node_first as usize);
    for l in 0..last {
        let src = level_src(l);
        let first = levels[l].node_first as u32;
        let parent_first = if l == 0 {
            0
        } else {
            levels[l - 1].node_first as u32
        };
        let parent_of: Vec<u32> = if l == 0 {
            vec![u32::MAX]
        } else {
            let mut p = vec![0u32; order[l].len()];
            for (pi, r) in child_ranges[l - 1].iter().enumerate() {
                for c in r.clone() {
                    p[c as usize] = parent_first + pi as u32;
                }
            }
            p
        };
        let point_level = (l + delta_n).min(last);
        let point_ranges = descendant_ranges(&child_ranges, l, point_level);
        // Written straight into `nodes` (its capacity holds every level): no temporary
        // of the level, whose fresh pages the kernel would zero once more.
        nodes.par_extend(order[l].par_iter().enumerate().map(|(i, &b)| {
            let rep = src
                .reps()
                .expect("levels above the finest are representatives");
            let rep = &rep.0[b as usize];
            let cr = &child_ranges[l][i];
            let pr = &point_ranges[i];
            NodeRecord {
                child_first: cr.start,
                child_count: cr.end - cr.start,
                point_first: pr.start,
                point_count: pr.end - pr.start,
                parent: parent_of[i],
                quant_node: first + i as u32,
                point_level: point_level as u8,
                ..rep.node(l)
            }
        }));
    }
    // A logarithm stored: each node's, of its mean value.
    if extras.attribute_log10 && particles.attribute.is_some() {
        nodes
            .par_iter_mut()
            .for_each(|n| n.attribute = n.attribute.log10());
    }
    // Encoding node = ancestor on level max(0, point_level - delta_n).
    for id in 0..nodes.len() {
        let n = nodes[id];
        let ql = (n.point_level as usize).saturating_sub(delta_n);
        let mut anc = id;
        for _ in ql..n.level as usize {
            anc = nodes[anc].parent as usize;
        }
        nodes[id].quant_node = anc as u32;
    }

    progress.advance(n as u64 / 4);
    // 5. Quantization: scales from the largest offsets of every encoded level.
    let bits = params.position_bits;
    let positions: Vec<Vec<[f32; 3]>> = (0..level_count)
        .map(|l| {
            let src = level_src(l);
            order[l]
                .par_iter()
                .map(|&b| src.position(b as usize))
                .collect()
        })
        .collect();
    let mut max_offset = vec![[0.0f64; 3]; nodes.len()];
    for m in 1..level_count {
        let ql = m.saturating_sub(delta_n);
        let ranges = descendant_ranges(&child_ranges, ql, m);
        let first = levels[ql].node_first as usize;
        let offs: Vec<[f64; 3]> = ranges
            .par_iter()
            .enumerate()
            .map(|(i, r)| {
                let c = nodes[first + i].centroid;
                let mut mo = [0.0f64; 3];
                for p in &positions[m][r.start as usize..r.end as usize] {
                    for k in 0..3 {
                        mo[k] = mo[k].max((f64::from(p[k]) - f64::from(c[k])).abs());
                    }
                }
                mo
            })
            .collect();
        for (i, o) in offs.into_iter().enumerate() {
            let mo = &mut max_offset[first + i];
            for k in 0..3 {
                mo[k] = mo[k].max(o[k]);
            }
        }
    }
    for (node, mo) in nodes.iter_mut().zip(&max_offset) {
        node.quant_scale = quantize::scale_for(*mo, bits);
    }
    let mut quantized = vec![Vec::new()];
    let mut max_err = 0.0f64;
    for m in 1..level_count {
        let ql = m.saturating_sub(delta_n);
        let first = levels[ql].node_first as u32;
        // The encoding node of every point of level m.
        let mut encoder = vec![0u32; positions[m].len()];
        for (i, r) in descendant_ranges(&child_ranges, ql, m).iter().enumerate() {
            encoder[r.start as usize..r.end as usize].fill(first + i as u32);
        }
        let encoded: Vec<[u16; 3]> = positions[m]
            .par_iter()
            .zip(&encoder)
            .map(|(p, &e)| {
                let node = &nodes[e as usize];
                [0, 1, 2].map(|k| {
                    quantize::encode(f64::from(p[k]), node.centroid[k], node.quant_scale[k], bits)
                })
            })
            .collect();
        if m == last {
            // The error actually made, decoded exactly as readers decode (the maximum
            // does not depend on the order of reduction).
            max_err = positions[m]
                .par_iter()
                .zip(&encoded)
                .zip(&encoder)
                .map(|((p, q), &e)| {
                    let node = &nodes[e as usize];
                    let d = quantize::decode3(*q, node.centroid, node.quant_scale, bits);
                    (0..3)
                        .map(|k| (f64::from(d[k]) - f64::from(p[k])).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .reduce(|| 0.0, f64::max);
        }
        quantized.push(encoded);
    }
    let top_positions = positions.into_iter().take(extras.keep_levels).collect();
    let root = coarser.last().expect("the top level").0[0];
    let particle_order = order.pop().expect("finest level");
    let species_index = particle_order
        .par_iter()
        .map(|&i| particles.species_index[i as usize])
        .collect();
    let attribute = particles.attribute.map(|a| {
        let stored = |v: f32| if extras.attribute_log10 { v.log10() } else { v };
        let (min, max) = extras.attribute_range.unwrap_or_else(|| {
            a.iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(stored(v)), hi.max(stored(v)))
                })
        });
        let span = max - min;
        let q = particle_order
            .par_iter()
            .map(|&i| {
                if span > 0.0 {
                    ((stored(a[i as usize]) - min) / span * 65535.0)
                        .round()
                        .clamp(0.0, 65535.0) as u16
                } else {
                    0
                }
            })
            .collect();
        (q, min, max)
    });
    let radius = radius_q.zip(radius_info).map(|(q, info)| {
        let ordered = particle_order.par_iter().map(|&i| q[i as usize]).collect();
        (ordered, info)
    });
    progress.advance(n as u64 - 3 * (n as u64 / 4));
    progress.finish_stage();
    Ok(Hierarchy {
        params: params.clone(),
        levels,
        nodes,
        quantized,
        particle_order,
        species_index,
        attribute,
        radius,
        extra_attributes: Vec::new(),
        max_position_error: max_err,
        root,
        top_positions,
    })
}

/// For every point of level `from`, the range of its descendants on level `to ≥ from`.
fn descendant_ranges(child_ranges: &[Vec<Range<u32>>], from: usize, to: usize) -> Vec<Range<u32>> {
    let count = if from == 0 {
        1
    } else {
        child_ranges[from - 1]
            .iter()
            .map(|r| r.end - r.start)
            .sum::<u32>() as usize
    };
    let mut ranges: Vec<Range<u32>> = (0..count as u32).map(|i| i..i + 1).collect();
    for l in from..to {
        let cr = &child_ranges[l];
        for r in &mut ranges {
            *r = cr[r.start as usize].start..cr[r.end as usize - 1].end;
        }
    }
    ranges
}

/// Largest coordinate magnitude a build accepts: node boxes and the differences of
/// coordinates stay finite in single precision (whose largest value is 3.4e38).
pub const MAX_COORDINATE: f32 = 1e37;

/// Largest sum of squared particle radii a build accepts: nodes record the sum of their
/// particles' `r²` (the flux of Eq. 1) in single precision, the top node's over all.
pub const MAX_AREA_SUM: f64 = 1e38;

/// Whether a position is one a build accepts (finite is checked separately).
#[inline]
pub fn position_in_range(p: &[f32; 3]) -> bool {
    p.iter().all(|v| v.abs() <= MAX_COORDINATE)
}

/// Most species a file holds (FORMAT.md: 1 to 65535).
pub const MAX_SPECIES: usize = 65535;

/// Checks the species table: at most [`MAX_SPECIES`] species, and radii such that
/// `particles` particles of the largest keep every node's sum of squared radii finite
/// (an upper bound: each particle counted at that radius). For chunked builds, call it
/// with the whole frame's count.
pub fn check_species(particles: usize, species: &[Species]) -> Result<(), BuildError> {
    if species.len() > MAX_SPECIES {
        return Err(BuildError::TooManySpecies(species.len()));
    }
    for s in species {
        // A species of several sizes: its largest particles'.
        let largest = s.radius_range.map_or(s.radius, |[_, hi]| hi.max(s.radius));
        let r = f64::from(largest);
        let sum = particles as f64 * r * r;
        if !(sum <= MAX_AREA_SUM && r <= f64::from(MAX_COORDINATE)) {
            return Err(BuildError::RadiusTooLarge {
                name: s.name.clone(),
                radius: largest,
                particles,
                sum,
            });
        }
    }
    Ok(())
}

impl BuildParams {
    /// Checks the parameters (before any particle is read: see
    /// [`crate::chunked::convert_chunked`]).
    pub fn check(&self) -> Result<(), BuildError> {
        let params = self;
        if params.max_cluster_size < 2 {
            return Err(BuildError::Params(format!(
                "max cluster size {} (must be at least 2)",
                params.max_cluster_size
            )));
        }
        if params.max_root_points < params.max_cluster_size {
            return Err(BuildError::Params(format!(
                "max root points {} is below the max cluster size {}",
                params.max_root_points, params.max_cluster_size
            )));
        }
        if params.position_bits != 8 && params.position_bits != 16 {
            return Err(BuildError::Params(format!(
                "position bits {} (must be 8 or 16)",
                params.position_bits
            )));
        }
        if params.delta_n == 0 || params.delta_n > 8 {
            return Err(BuildError::Params(format!(
                "delta_n {} (must be 1 to 8)",
                params.delta_n
            )));
        }
        Ok(())
    }
}

fn validate(p: &Particles<'_>, params: &BuildParams) -> Result<(), BuildError> {
    params.check()?;
    let n = p.positions.len();
    if n == 0 {
        return Err(BuildError::Empty);
    }
    if n > u32::MAX as usize {
        return Err(BuildError::TooMany(n));
    }
    if p.species_index.len() != n
        || p.attribute.is_some_and(|a| a.len() != n)
        || p.radii.is_some_and(|r| r.len() != n)
    {
        return Err(BuildError::Params(
            "per-particle arrays differ in length".into(),
        ));
    }
    if let Some(index) = p
        .positions
        .iter()
        .position(|x| x.iter().any(|v| !v.is_finite()))
    {
        return Err(BuildError::NonFinite {
            index,
            position: p.positions[index],
        });
    }
    if let Some(index) = p.positions.iter().position(|x| !position_in_range(x)) {
        return Err(BuildError::OutOfRange {
            index,
            position: p.positions[index],
        });
    }
    if let Some(a) = p.attribute {
        if let Some(index) = a.iter().position(|v| !v.is_finite()) {
            return Err(BuildError::NonFiniteAttribute {
                index,
                value: a[index],
            });
        }
    }
    // Particles' own radii first: a huge one makes its species' mean huge too, and the
    // message should name the particle.
    if let Some(r) = p.radii {
        if let Some(index) = r.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(BuildError::BadRadius {
                index,
                radius: r[index],
            });
        }
        let index = (0..n).fold(0, |m, i| if r[i] > r[m] { i } else { m });
        let largest = r[index];
        let sum = n as f64 * f64::from(largest).powi(2);
        if !(sum <= MAX_AREA_SUM && largest <= MAX_COORDINATE) {
            return Err(BuildError::ParticleRadiusTooLarge {
                index,
                radius: largest,
                particles: n,
                sum,
            });
        }
    }
    check_species(n, p.species)?;
    if let Some(index) = p
        .species_index
        .iter()
        .position(|&s| usize::from(s) >= p.species.len())
    {
        return Err(BuildError::BadSpecies {
            index,
            species: p.species_index[index],
            count: p.species.len(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts what a build reports.
    #[derive(Default)]
    struct Counted {
        stages: std::sync::Mutex<Vec<(String, Option<u64>, &'static str)>>,
        done: std::sync::atomic::AtomicU64,
    }

    impl Progress for Counted {
        fn stage(&self, name: &str, total: Option<u64>, unit: &'static str) {
            self.stages
                .lock()
                .unwrap()
                .push((name.to_string(), total, unit));
        }
        fn advance(&self, amount: u64) {
            self.done
                .fetch_add(amount, std::sync::atomic::Ordering::Relaxed);
        }
    }

    #[test]
    fn the_build_reports_its_particles_once_in_all() {
        // 100 003 points (odd, and above the size split on threads of their own): the bar
        // ends at the particle count, not twice it.
        let n = 100_003;
        let positions: Vec<[f32; 3]> = (0..n)
            .map(|i| [(i % 97) as f32, ((i / 97) % 101) as f32, (i / 9797) as f32])
            .collect();
        let species_index = vec![0u16; n];
        let species = [Species {
            name: "X".into(),
            radius: 0.5,
            colour: [1.0; 3],
            radius_range: None,
        }];
        let counted = Counted::default();
        build(
            Particles {
                positions: &positions,
                species_index: &species_index,
                species: &species,
                attribute: None,
                radii: None,
            },
            &BuildParams::default(),
            &counted,
        )
        .unwrap();
        let stages = counted.stages.into_inner().unwrap();
        assert_eq!(
            stages,
            [(
                "building hierarchy".to_string(),
                Some(n as u64),
                "particles"
            )]
        );
        assert_eq!(counted.done.into_inner(), n as u64);
    }

    #[test]
    fn particles_of_their_own_sizes_keep_flux_bounds_and_a_bounded_radius_error() {
        // 20 000 particles of one species with radii from 0.1 to 2.9.
        let n = 20_000;
        let mut seed = 7u64;
        let mut rand = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let positions: Vec<[f32; 3]> = (0..n)
            .map(|_| [rand() * 50.0, rand() * 50.0, rand() * 50.0])
            .collect();
        let radii: Vec<f32> = (0..n).map(|_| 0.1 + 2.8 * rand()).collect();
        let species_index = vec![0u16; n];
        let species = [Species {
            name: "grain".into(),
            radius: 1.5,
            colour: [0.5; 3],
            radius_range: Some([0.1, 2.9]),
        }];
        let own = particle_radii(&species, &species_index, Some(&radii)).unwrap();
        let build_of = |radii: &[f32]| {
            build(
                Particles {
                    positions: &positions,
                    species_index: &species_index,
                    species: &species,
                    attribute: None,
                    radii: Some(radii),
                },
                &BuildParams::default(),
                &NoProgress,
            )
        };
        let h = build_of(&own).unwrap();
        let (q, info) = h.radius.as_ref().expect("radii kept");
        let lo = radii.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = radii.iter().copied().fold(0.0, f32::max);
        assert_eq!((info.min, info.max), (lo, hi));
        // Half a step of 16 bits over the range, and the single-precision rounding.
        let bound = (hi - lo) / 65535.0 / 2.0 + 4.0 * f32::EPSILON * hi;
        let decoded: Vec<f32> = q.iter().map(|&q| info.decode(q)).collect();
        for (k, &i) in h.particle_order.iter().enumerate() {
            let err = (decoded[k] - radii[i as usize]).abs();
            assert!(err <= bound, "particle {i}: error {err} above {bound}");
        }
        // Flux (Eq. 1): the top node's Σ r² is the particles' own, as decoded.
        let sum: f64 = decoded.iter().map(|&r| f64::from(r) * f64::from(r)).sum();
        let top = f64::from(h.nodes[0].area_sum);
        assert!((top - sum).abs() <= 1e-5 * sum, "{top} against {sum}");
        // Every parent of particles holds its particles' own spheres, and is drawn at
        // least as large as the largest.
        let last = h.level_count() - 1;
        let first = h.levels[last - 1].node_first as usize;
        let count = h.levels[last - 1].point_count as usize;
        for node in &h.nodes[first..first + count] {
            for c in node.child_first..node.child_first + node.child_count {
                let i = h.particle_order[c as usize] as usize;
                let (p, r) = (positions[i], decoded[c as usize]);
                // Its own sphere, and its species' (what a 1.0 reader draws).
                for r in [r, 1.5] {
                    for d in 0..3 {
                        assert!(node.bounds_min[d] <= p[d] - r + 1e-4);
                        assert!(node.bounds_max[d] >= p[d] + r - 1e-4);
                    }
                }
                assert!(node.radius >= r * (1.0 - 1e-6), "{} < {r}", node.radius);
            }
        }
        // The range: the species with particles only.
        let two = [
            species[0].clone(),
            Species {
                name: "unused".into(),
                radius: 9.0,
                colour: [0.5; 3],
                radius_range: None,
            },
        ];
        let info = radius_range(&two, &[n as u64, 0]).unwrap();
        assert_eq!((info.min, info.max), (0.1, 2.9));
        assert_eq!(radius_range(&two, &[n as u64, 1]).unwrap().max, 9.0);
        // Without sizes of its own, or with the species of one size, none are kept.
        let one = [Species {
            radius_range: None,
            ..species[0].clone()
        }];
        assert!(particle_radii(&one, &species_index, Some(&radii)).is_none());
        assert!(particle_radii(&species, &species_index, None).is_none());
        // A radius that is not a finite number from 0 up is refused, naming the particle.
        let mut bad = own.clone();
        bad[17] = f32::NAN;
        let e = build_of(&bad).unwrap_err();
        assert!(matches!(e, BuildError::BadRadius { index: 17, .. }), "{e}");
    }

    #[test]
    fn more_nodes_than_32_bits_number_are_refused_before_writing() {
        let table = |counts: &[u64]| -> Vec<LevelRecord> {
            counts
                .iter()
                .map(|&point_count| LevelRecord {
                    point_count,
                    node_first: 0,
                    reserved: [0; 2],
                })
                .collect()
        };
        // Every level within 2^32 − 1 points; the particles' own level does not count.
        let fits = table(&[1, 1 << 31, (1 << 31) - 2, 1 << 32]);
        assert!(check_node_total(&fits).is_ok());
        let over = table(&[1, 1 << 31, (1 << 31) - 1, 5]);
        match check_node_total(&over) {
            Err(BuildError::TooManyNodes(n)) => assert_eq!(n, 1 << 32),
            other => panic!("{other:?}"),
        }
    }
}
