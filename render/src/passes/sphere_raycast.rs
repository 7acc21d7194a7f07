//! The sphere ray-casting pass (`sphere_raycast.wgsl`): one depth-correct impostor per
//! drawn point, positions decoded on the GPU from the file's quantized words.
//!
//! How it works: [`pack`] turns a [`DrawList`] into four flat arrays, copying (not
//! decoding) file data: the raw position words of every range (each range padded to
//! a whole u32), per point either its species index (particles, two per u32) or its
//! node's radius and colour (representatives), one [`RangeGpu`] per range (base, scale,
//! offsets into the other arrays) and one range index per point. The pass draws
//! `points` instances of a 4-vertex strip in a single call (measured faster on an H200
//! than 6 non-instanced vertices per point); see the WGSL for the shading. The
//! `#[repr(C)]` structs here mirror the WGSL structs field for field.
//!
//! Small spheres ([`SmallSpheres`], `small_spheres.wgsl`), where the device has 64-bit
//! atomics: a sphere a pixel or two wide costs a rasterizer two triangles and a quad of
//! fragments for one or two pixels, and in a dense data set seen whole almost every
//! sphere is that small. Each sample of a sphere frame then starts with a compute pass,
//! one invocation per point: a sphere whose screen box spans at most
//! [`SMALL_SPHERE_MAX_SIDE`] pixel centres each way traces the rays of those centres and
//! offers `(entry depth, point index)` to each pixel it covers, by a 64-bit atomic maximum
//! of the key's complement (the nearest entry wins, ties to the lower index, so the
//! result does not depend on the order the invocations run in). A sphere larger than
//! that, or reaching the near or far plane, is appended to a list whose length is the
//! instance count of an indirect draw. The render pass then draws a full-screen triangle
//! that shades each pixel's winner and writes its depth (`fs_resolve`), and the listed
//! spheres as impostors against that depth (`vs_listed`). The rays and the shading are
//! those of the impostors, so the two paths agree up to rounding on silhouettes (tested).

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use mdlod_format::{FormatError, MdlodFile};

use crate::error::RenderError;
use crate::style::{pack_colour, AttributeScale, PointStyle};
use crate::traversal::{representative_radius, DrawList};

/// The shared point decoding (uniforms, bindings, `load_point`) every point pass starts
/// with.
pub const POINTS_WGSL: &str = include_str!("points.wgsl");

/// WGSL source of the pass: `points.wgsl`, `pixel_rays.wgsl` and `sphere_raycast.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("points.wgsl"),
    "\n",
    include_str!("pixel_rays.wgsl"),
    "\n",
    include_str!("sphere_raycast.wgsl")
);

/// WGSL source of the small-sphere raster (a compute pass that needs 64-bit integer
/// atomics): `points.wgsl`, `pixel_rays.wgsl` and `small_spheres.wgsl`.
pub const SMALL_SPHERES_SHADER: &str = concat!(
    include_str!("points.wgsl"),
    "\n",
    include_str!("pixel_rays.wgsl"),
    "\n",
    include_str!("small_spheres.wgsl")
);

/// The features the small-sphere raster needs.
pub const SMALL_SPHERES_FEATURES: wgpu::Features =
    wgpu::Features::SHADER_INT64.union(wgpu::Features::SHADER_INT64_ATOMIC_MIN_MAX);

/// Largest side, in pixel centres, of a sphere's screen box that the small-sphere raster
/// draws; larger spheres are drawn as impostor quads.
pub const SMALL_SPHERE_MAX_SIDE: u32 = 8;

/// `Raster` in `pixel_rays.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RasterUniforms {
    pub size: [u32; 2],
    pub points: u32,
    pub max_side: u32,
    pub row: u32,
    pub pad: [u32; 3],
}

/// The source with the fragment stage declared conservative (its depth is never nearer
/// than the rasterized quad's: never greater, in reversed depth), for devices with
/// `SHADER_EARLY_DEPTH_TEST`.
pub fn shader_source(early_depth: bool) -> String {
    if early_depth {
        // Both fragment stages write a depth never nearer than the rasterized quad's.
        SHADER
            .replace(
                "@fragment\nfn fs_main",
                "@fragment @early_depth_test(less_equal)\nfn fs_main",
            )
            .replace(
                "@fragment\nfn fs_gbuffer",
                "@fragment @early_depth_test(less_equal)\nfn fs_gbuffer",
            )
    } else {
        SHADER.to_string()
    }
}

/// Format of the colour target the pass draws into (linear, for accumulation).
pub const COLOUR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// Format of the G-buffer targets (view-space normal and coverage; albedo).
pub const GBUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// Format of the depth target.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// `Frame` in the WGSL: per-sample uniforms.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameUniforms {
    pub clip_from_view: [[f32; 4]; 4],
    pub view_from_world: [[f32; 4]; 4],
    /// xyz: unit vector towards the light, in view space.
    pub light_dir_view: [f32; 4],
    /// ambient, diffuse, specular, shininess.
    pub material: [f32; 4],
    /// x: 1 for orthographic; y: H = (2^bits − 1) / 2.
    pub params: [f32; 4],
    /// x: position bits; y: species count.
    pub counts: [u32; 4],
    /// rgb: the light's colour (linear; it scales the diffuse and specular terms).
    pub light_colour: [f32; 4],
}

/// `Range` in the WGSL: one run of points decoded with one base and scale.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct RangeGpu {
    pub base: [f32; 3],
    /// First u32 of the range's quantized positions in the positions buffer.
    pub word_offset: u32,
    pub scale: [f32; 3],
    /// Particles: first u32 of the species indices (two u16 per word);
    /// representatives: first u32 of the (radius, colour) pairs.
    pub attr_offset: u32,
    /// Instance index of the range's first point.
    pub first_point: u32,
    /// [`KIND_PARTICLE`], [`KIND_NODE`], [`KIND_INTENSITY`], [`KIND_SIZED`] or
    /// [`KIND_PARTICLE_INTENSITY`].
    pub kind: u32,
    /// Index of the range's first point within its block of words: point `j` of the
    /// range is point `j + point_offset` of the block starting at `word_offset` /
    /// `attr_offset` (0 when a range has its own words; a page offset when streaming).
    pub point_offset: u32,
    pub pad: u32,
}

pub const KIND_PARTICLE: u32 = 0;
/// Per point a radius (f32) and a colour as sRGB bytes (`style::pack_colour`): clusters,
/// and particles coloured by a map.
pub const KIND_NODE: u32 = 1;
/// Per point a radius and a grey intensity, both f32 (splats by attribute): clusters.
pub const KIND_INTENSITY: u32 = 2;
/// A particle of a file with per-particle radii: its species index (u32) and its drawn
/// radius (f32).
pub const KIND_SIZED: u32 = 3;
/// A particle's [`KIND_INTENSITY`] record: the density weighs it as a particle, not as a
/// representative.
pub const KIND_PARTICLE_INTENSITY: u32 = 4;

const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 208);
const _: () = assert!(std::mem::size_of::<RangeGpu>() == 48);

/// The lighting: one directional light fixed in view space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Direction towards the light in view space (x right, y up, z towards the viewer).
    pub direction_view: Vec3,
    /// The light's colour, linear (white by default): it scales the diffuse and
    /// specular light; the ambient light stays white.
    pub colour: [f32; 3],
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            direction_view: Vec3::new(-0.35, 0.45, 1.0).normalize(),
            colour: [1.0; 3],
            ambient: 0.15,
            diffuse: 0.85,
            specular: 0.25,
            shininess: 32.0,
        }
    }
}

impl FrameUniforms {
    pub fn new(
        clip_from_view: Mat4,
        view_from_world: Mat4,
        orthographic: bool,
        lighting: &Lighting,
        position_bits: u32,
        species_count: u32,
    ) -> Self {
        let l = lighting.direction_view.normalize_or(Vec3::Z);
        FrameUniforms {
            clip_from_view: clip_from_view.to_cols_array_2d(),
            view_from_world: view_from_world.to_cols_array_2d(),
            light_dir_view: [l.x, l.y, l.z, 0.0],
            material: [
                lighting.ambient,
                lighting.diffuse,
                lighting.specular,
                lighting.shininess,
            ],
            params: [
                if orthographic { 1.0 } else { 0.0 },
                mdlod_format::quantize::half_range(position_bits),
                0.0,
                0.0,
            ],
            counts: [position_bits, species_count, 0, 0],
            light_colour: [
                lighting.colour[0],
                lighting.colour[1],
                lighting.colour[2],
                0.0,
            ],
        }
    }
}

/// A draw list flattened for the GPU (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct PackedDraw {
    pub positions: Vec<u32>,
    pub attrs: Vec<u32>,
    pub ranges: Vec<RangeGpu>,
    pub point_range: Vec<u32>,
    /// Species table: linear albedo and radius.
    pub species: Vec<[f32; 4]>,
    pub position_bits: u32,
}

impl PackedDraw {
    pub fn points(&self) -> u32 {
        self.point_range.len() as u32
    }

    /// Bytes of the largest of the storage buffers.
    /// Bytes of all the buffers the cut uploads.
    pub fn data_bytes(&self) -> u64 {
        (self.positions.len() * 4
            + self.attrs.len() * 4
            + self.ranges.len() * 48
            + self.point_range.len() * 4
            + self.species.len() * 16) as u64
    }

    pub fn largest_buffer_bytes(&self) -> u64 {
        [
            self.positions.len() * 4,
            self.attrs.len() * 4,
            self.ranges.len() * 48,
            self.point_range.len() * 4,
            self.species.len() * 16,
        ]
        .into_iter()
        .max()
        .unwrap_or(0) as u64
    }

    /// What the vertex shader computes for point `i`: world position, radius, albedo.
    /// (A CPU twin of the shader's decoding, for tests.)
    pub fn decode_point(&self, i: u32) -> ([f32; 3], f32, [f32; 3]) {
        let r = &self.ranges[self.point_range[i as usize] as usize];
        let j = i - r.first_point + r.point_offset;
        let word = |w: u32| self.positions[w as usize];
        let q: [u16; 3] = std::array::from_fn(|k| {
            let k = 3 * j + k as u32;
            if self.position_bits == 16 {
                (word(r.word_offset + (k >> 1)) >> ((k & 1) * 16)) as u16
            } else {
                ((word(r.word_offset + (k >> 2)) >> ((k & 3) * 8)) & 0xff) as u16
            }
        });
        let h = mdlod_format::quantize::half_range(self.position_bits);
        let pos = std::array::from_fn(|k| r.base[k] + r.scale[k] * (f32::from(q[k]) - h));
        if r.kind == KIND_PARTICLE {
            let hw = r.attr_offset * 2 + j;
            let s = ((self.attrs[(hw >> 1) as usize] >> ((hw & 1) * 16)) & 0xffff) as usize;
            let sp = self.species[s.min(self.species.len() - 1)];
            (pos, sp[3], [sp[0], sp[1], sp[2]])
        } else if r.kind == KIND_INTENSITY || r.kind == KIND_PARTICLE_INTENSITY {
            let a = (r.attr_offset + 2 * j) as usize;
            let v = f32::from_bits(self.attrs[a + 1]);
            (pos, f32::from_bits(self.attrs[a]), [v; 3])
        } else if r.kind == KIND_SIZED {
            let a = (r.attr_offset + 2 * j) as usize;
            let s = (self.attrs[a] as usize).min(self.species.len() - 1);
            let sp = self.species[s];
            (
                pos,
                f32::from_bits(self.attrs[a + 1]),
                [sp[0], sp[1], sp[2]],
            )
        } else {
            let a = (r.attr_offset + 2 * j) as usize;
            (
                pos,
                f32::from_bits(self.attrs[a]),
                crate::style::unpack_colour(self.attrs[a + 1]),
            )
        }
    }
}

/// Appends `bytes` as little-endian u32 words, the last one zero-padded.
pub fn push_bytes_as_words(out: &mut Vec<u32>, bytes: &[u8]) {
    let mut chunks = bytes.chunks_exact(4);
    for c in &mut chunks {
        out.push(u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let mut w = [0u8; 4];
        w[..rest.len()].copy_from_slice(rest);
        out.push(u32::from_le_bytes(w));
    }
}

/// Flattens `draw` for the GPU. Species indices are checked here (opening a file does not
/// read them), so a corrupt index is an error naming the particle, not a wrong colour.
pub fn pack(file: &MdlodFile, draw: &DrawList) -> Result<PackedDraw, RenderError> {
    pack_styled(file, draw, PackStyle::Spheres, &PointStyle::default())
}

/// What the per-point attributes of a packed cut carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PackStyle {
    /// Spheres: representatives at their coverage radius with their colour.
    Spheres,
    /// Flux-preserving splats coloured by species: representatives at `sqrt(area_sum)`.
    FluxColour,
    /// Flux-preserving splats whose intensity is the scalar attribute mapped from its
    /// range to [0, 1] (an affine map keeps the area-weighted means of the
    /// representatives exact; a constant attribute maps to 1): every point is a
    /// [`KIND_INTENSITY`] record. The image's light is then brought to the attribute's
    /// own units by one factor ([`AttrPacker::light_unit`]), after the accumulation in
    /// 32-bit floats, which values in any units (masses in grams) would overflow.
    FluxAttribute,
    /// Flux-preserving points whose grey value is the attribute's place on its colour
    /// scale, in [0, 1] (its range, or the one asked for, and its logarithm where asked):
    /// the iso-surface coloured by the attribute averages these with the density's
    /// weights and looks the mean up in the colour map, so that every colour on the
    /// surface is one on the colour bar; the volume coloured by it weighs the places by
    /// the points' densities at each sample. Records as [`PackStyle::FluxAttribute`]'s.
    FluxValue,
}

/// Flattens `draw` for the GPU with the points packed as `style` says and their look
/// changed by `look` (spheres only; see [`crate::style`]).
pub fn pack_styled(
    file: &MdlodFile,
    draw: &DrawList,
    style: PackStyle,
    look: &PointStyle,
) -> Result<PackedDraw, RenderError> {
    let packer = AttrPacker::new(file, style, look)?;
    let bits = file.position_bits();
    let bytes_per_point = 3 * (bits as usize / 8);
    let nodes = file.nodes();
    let mut out = PackedDraw {
        position_bits: bits,
        species: packer.species.clone(),
        ..Default::default()
    };
    out.point_range.reserve(draw.points as usize);
    for (ri, r) in draw.ranges.iter().enumerate() {
        let level = usize::from(r.level);
        let (first, count) = (r.first as usize, r.count as usize);
        let enc = &nodes[r.quant_node as usize];
        let word_offset = out.positions.len() as u32;
        let attr_offset = out.attrs.len() as u32;
        let (base, scale) = if level == 0 {
            // The top node itself: no stored position; scale 0 decodes to the centroid.
            push_bytes_as_words(&mut out.positions, &vec![0u8; bytes_per_point]);
            (nodes[0].centroid, [0.0; 3])
        } else {
            let pos = file.positions(level);
            let bytes = &pos.bytes()[first * bytes_per_point..(first + count) * bytes_per_point];
            push_bytes_as_words(&mut out.positions, bytes);
            (enc.centroid, enc.quant_scale)
        };
        let kind = packer.push(file, level, first, count, &mut out.attrs)?;
        out.ranges.push(RangeGpu {
            base,
            word_offset,
            scale,
            attr_offset,
            first_point: out.point_range.len() as u32,
            kind,
            point_offset: 0,
            pad: 0,
        });
        out.point_range
            .extend(std::iter::repeat_n(ri as u32, count));
    }
    Ok(out)
}

/// Makes the per-point attribute words of a cut's ranges for one [`PackStyle`] and look:
/// the packer of whole cuts ([`pack_styled`]) and of the streaming pool's pages, so both
/// draw the same points. At most two words per point.
#[derive(Clone, Debug)]
pub struct AttrPacker {
    style: PackStyle,
    radius_scale: f32,
    /// Colouring by the attribute: the map and the attribute's scale.
    mapped: Option<(crate::style::ColourMap, AttributeScale)>,
    /// Intensities from the attribute ([`PackStyle::FluxAttribute`]).
    intensity: Option<AttributeScale>,
    /// The styled species table: linear albedo and radius.
    pub species: Vec<[f32; 4]>,
    /// The map that recolours clusters after species colours changed
    /// ([`PointStyle::cluster_recolour`]).
    recolour: Option<[[f32; 4]; 3]>,
    /// The file's species count (indices at or above it are corrupt).
    species_count: usize,
    /// Per species, the drawn radius of a particle of the file's per-particle radii
    /// over its own: the styled radius over the file's (an override scales the
    /// species' sizes; 0 when hidden).
    size_factor: Vec<f32>,
    /// The file keeps per-particle radii.
    sized: bool,
    /// Colouring by the attribute: species whose colour the style sets keep it (walls
    /// grey beside grains coloured by speed), by species index.
    fixed: Vec<Option<[f32; 3]>>,
    /// Per node, the one species below it ([`MdlodFile::pure_species`]), where the
    /// style changes colours (a colour set, a species hidden, walls kept under a map):
    /// such a cluster takes its species' colour exactly. Through the file's 8-bit linear
    /// mixture and the recolouring map it came out up to 6 levels off at the dark end
    /// with two species, and up to 187 with five (whose colours no affine map fits).
    pure: Option<std::sync::Arc<[u16]>>,
}

impl AttrPacker {
    /// Checks `look` against `file` (a colour map or attribute intensities need the
    /// attribute; styled species must exist). `look` applies to spheres only.
    pub fn new(file: &MdlodFile, style: PackStyle, look: &PointStyle) -> Result<Self, RenderError> {
        // The attribute's shown range and scale serve the intensities of splats too.
        let (range, log, derived) = (look.attribute_range, look.log_scale, look.range_derived);
        let default_look = PointStyle::default();
        let colours_only;
        let look = match style {
            PackStyle::Spheres => look,
            // Splats take the species' colours and keep the file's radii: a splat's flux
            // is its disk's area.
            PackStyle::FluxColour => {
                colours_only = PointStyle {
                    species: look
                        .species
                        .iter()
                        .map(|s| crate::style::SpeciesStyle {
                            radius: None,
                            ..s.clone()
                        })
                        .collect(),
                    palette: look.palette,
                    ..Default::default()
                };
                &colours_only
            }
            PackStyle::FluxAttribute | PackStyle::FluxValue => &default_look,
        };
        look.validate().map_err(RenderError::InvalidOptions)?;
        PointStyle {
            attribute_range: range,
            log_scale: log,
            ..Default::default()
        }
        .validate()
        .map_err(RenderError::InvalidOptions)?;
        let meta = file.metadata();
        let attribute = |what: &str| {
            meta.attribute
                .as_ref()
                .map(|info| AttributeScale::with_range(info, range).with_log(log))
                .ok_or_else(|| {
                    RenderError::InvalidOptions(format!(
                        "{} has no per-particle attribute to {what} (a file keeps the one \
                         dump column `mdlod convert --attribute COLUMN` or `mdlod batch \
                         --attribute COLUMN` names, e.g. --attribute c_pe)",
                        file.path().display()
                    ))
                })
        };
        let mapped = match look.colour_map {
            Some(map) => Some((map, attribute("colour by")?)),
            None => None,
        };
        // (A logarithm stored with its clusters' mean values lights by the quantity.) The
        // light's range keeps its zero where mdlod chose the range.
        let lit = |quantity: bool| -> Result<AttributeScale, RenderError> {
            let shown = attribute("take intensities from")?;
            let Some(info) = meta.attribute.as_ref() else {
                return Ok(shown);
            };
            let ranged = PointStyle {
                attribute_range: range,
                range_derived: derived,
                ..Default::default()
            };
            let scale = AttributeScale::with_range(info, ranged.light_range(info, quantity));
            Ok(match quantity {
                true => scale.lighting_by_quantity(),
                false => scale.with_log(log),
            })
        };
        let intensity = match style {
            PackStyle::FluxAttribute if meta.attribute_log10 => Some(lit(true)?),
            PackStyle::FluxAttribute => Some(lit(false)?),
            PackStyle::FluxValue => Some(attribute("colour by")?),
            _ => None,
        };
        let species = look
            .species_table(&meta.species)
            .map_err(|e| RenderError::InvalidOptions(format!("{}: {e}", file.path().display())))?;
        let size_factor = species
            .iter()
            .zip(&meta.species)
            .map(|(t, s)| if s.radius > 0.0 { t[3] / s.radius } else { 0.0 })
            .collect();
        // Under a colour map, the species whose colour the style names keep it.
        let mut fixed = vec![None; meta.species.len()];
        if mapped.is_some() {
            for (i, s) in meta.species.iter().enumerate() {
                let styled = look.species.iter().find(|t| t.name == s.name && !t.hidden);
                fixed[i] = styled.and_then(|t| t.colour);
            }
        }
        let recolour = look.cluster_recolour(&meta.species, &species);
        let hides = look.species.iter().any(|t| t.hidden);
        let pure = (meta.species.len() > 1
            && (recolour.is_some() || hides || fixed.iter().any(Option::is_some)))
        .then(|| file.pure_species());
        Ok(AttrPacker {
            fixed,
            pure,
            size_factor,
            sized: file.radii().is_some(),
            style,
            radius_scale: look.radius_scale,
            mapped,
            intensity,
            recolour,
            species,
            species_count: meta.species.len(),
        })
    }

    /// The style the packer was made for.
    pub fn style(&self) -> PackStyle {
        self.style
    }

    /// What an intensity of 1 stands for in the attribute's units
    /// ([`AttributeScale::light_unit`]); 1 when the intensities are not the attribute's.
    pub fn light_unit(&self) -> f32 {
        if self.style == PackStyle::FluxValue {
            return 1.0;
        }
        self.intensity
            .as_ref()
            .map_or(1.0, AttributeScale::light_unit)
    }

    /// The attribute's scale the grey values come from ([`PackStyle::FluxAttribute`],
    /// [`PackStyle::FluxValue`]).
    pub fn value_scale(&self) -> Option<&AttributeScale> {
        self.intensity.as_ref()
    }

    /// The range kind of points on `level` (`last`: the file's finest level).
    pub fn kind(&self, level: usize, last: usize) -> u32 {
        if self.intensity.is_some() && level == last {
            KIND_PARTICLE_INTENSITY
        } else if self.intensity.is_some() {
            KIND_INTENSITY
        } else if self.mapped.is_some() || level != last {
            KIND_NODE
        } else if self.sized {
            KIND_SIZED
        } else {
            KIND_PARTICLE
        }
    }

    fn radius(&self, n: &mdlod_format::NodeRecord) -> f32 {
        match self.style {
            PackStyle::Spheres => representative_radius(n) * self.radius_scale,
            _ => n.area_sum.max(0.0).sqrt(),
        }
    }

    /// Appends the attribute words of points `first..first + count` of `level` to
    /// `attrs` and returns their range kind ([`Self::kind`]). Species indices are
    /// checked here (opening a file does not read them), so a corrupt index is an error
    /// naming the particle.
    pub fn push(
        &self,
        file: &MdlodFile,
        level: usize,
        first: usize,
        count: usize,
        attrs: &mut Vec<u32>,
    ) -> Result<u32, RenderError> {
        let last = file.level_count() - 1;
        let meta = file.metadata();
        let bad_species = |particle: usize, s: u16| {
            RenderError::Format(FormatError::Corrupt {
                path: file.path().to_path_buf(),
                place: format!("SPECIES, particle {particle}"),
                problem: format!("species index {s} but only {} species", self.species_count),
            })
        };
        let values = file.attribute().unwrap_or_default();
        let node_first = || file.levels()[level].node_first as usize + first;
        if level == last {
            let sp = &file.species()[first..first + count];
            if let Some(k) = sp
                .iter()
                .position(|&s| usize::from(s) >= self.species_count)
            {
                return Err(bad_species(first + k, sp[k]));
            }
            // Each particle's own radius where the file keeps them, as drawn (styled).
            let own = file.radii().zip(meta.radius.as_ref());
            let own_radius = |k: usize| own.map(|(q, _)| file.radius_of(q[first + k]));
            if let Some(scale) = &self.intensity {
                for (k, &s) in sp.iter().enumerate() {
                    let q = values.get(first + k).copied().unwrap_or(0);
                    let r = own_radius(k).unwrap_or(meta.species[usize::from(s)].radius);
                    attrs.push(r.to_bits());
                    attrs.push(scale.of_quantized(q).to_bits());
                }
            } else if let Some((map, scale)) = &self.mapped {
                // Radius and mapped colour per point, as cluster records are.
                for (k, &s) in sp.iter().enumerate() {
                    let q = values.get(first + k).copied().unwrap_or(0);
                    let r = match own_radius(k) {
                        Some(r) => r * self.size_factor[usize::from(s)],
                        None => self.species[usize::from(s)][3],
                    };
                    attrs.push(r.to_bits());
                    attrs.push(match self.fixed[usize::from(s)] {
                        Some(c) => pack_colour(c),
                        None => pack_colour(map.colour(scale.of_quantized(q))),
                    });
                }
            } else if own.is_some() {
                for (k, &s) in sp.iter().enumerate() {
                    let r = own_radius(k).unwrap_or(0.0) * self.size_factor[usize::from(s)];
                    attrs.push(u32::from(s));
                    attrs.push(r.to_bits());
                }
            } else {
                push_bytes_as_words(attrs, bytemuck::cast_slice(sp));
            }
        } else {
            // Records a traversal did not read (a streaming page's others) may not have
            // been checked yet.
            file.check_nodes(level, first..first + count)?;
            let nf = node_first();
            for (id, n) in (nf..).zip(&file.nodes()[nf..nf + count]) {
                attrs.push(self.radius(n).to_bits());
                // The one species of a cluster of one (a file of one species: every
                // cluster's), where known.
                let pure = match self.species_count {
                    1 => Some(0),
                    _ => self
                        .pure
                        .as_ref()
                        .and_then(|p| p.get(id).copied())
                        .map(usize::from)
                        .filter(|&s| s < self.species.len()),
                };
                attrs.push(if let Some(scale) = &self.intensity {
                    scale.of_value(n.attribute).to_bits()
                } else if let Some((map, scale)) = &self.mapped {
                    // A cluster of one species the colour map leaves its colour: that
                    // colour (a mixed one takes the map's colour of its mean).
                    match pure.and_then(|s| self.fixed.get(s).copied().flatten()) {
                        Some(c) => pack_colour(c),
                        None => pack_colour(map.colour(scale.of_value(n.attribute))),
                    }
                } else if let Some(s) = pure {
                    let c = self.species[s];
                    pack_colour([c[0], c[1], c[2]])
                } else if let Some(t) = &self.recolour {
                    pack_colour(crate::style::recoloured(t, n.colour_rgb()))
                } else {
                    crate::style::pack_file_colour(n.colour)
                });
            }
        }
        Ok(self.kind(level, last))
    }
}

/// A read-only storage buffer holding `bytes`; bindings must not be empty, so an empty
/// array gets one zero word.
pub fn storage_buffer(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let zero = [0u8; 16];
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: if bytes.is_empty() { &zero } else { bytes },
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// The pipelines (shaded, and the S-NDF G-buffer of normals and albedos) and their bind
/// group layout.
pub struct SphereRaycastPass {
    pub pipeline: wgpu::RenderPipeline,
    pub gbuffer: wgpu::RenderPipeline,
    pub layout: wgpu::BindGroupLayout,
    /// The small-sphere raster, where the device has [`SMALL_SPHERES_FEATURES`].
    pub small: Option<SmallSpheres>,
}

/// The pipelines of the small-sphere raster (`small_spheres.wgsl`) and of the sphere
/// pass's side of it (`fs_resolve`, `vs_listed`).
pub struct SmallSpheres {
    raster: wgpu::ComputePipeline,
    resolve: wgpu::RenderPipeline,
    listed: wgpu::RenderPipeline,
    /// The same into the S-NDF sampling's G-buffer (normal, albedo).
    resolve_gbuffer: wgpu::RenderPipeline,
    listed_gbuffer: wgpu::RenderPipeline,
    /// The impostors' indirect draw with no instance, copied in before each raster.
    args_init: wgpu::Buffer,
    raster_layout: wgpu::BindGroupLayout,
    draw_layout: wgpu::BindGroupLayout,
}

/// One frame's buffers of the small-sphere raster (see [`SmallSpheres::prepare`]).
pub struct SmallSphereTargets {
    uniforms: wgpu::Buffer,
    visible: wgpu::Buffer,
    large: wgpu::Buffer,
    args: wgpu::Buffer,
    args_read: wgpu::Buffer,
    raster_group: wgpu::BindGroup,
    draw_group: wgpu::BindGroup,
    /// This frame's dispatch and the bytes of `visible` its image uses.
    groups: [u32; 2],
    visible_bytes: u64,
}

/// The storage buffers the pass reads (see the WGSL bindings 1 to 5).
#[derive(Clone, Copy)]
pub struct SphereInputs<'a> {
    pub positions: &'a wgpu::Buffer,
    pub attrs: &'a wgpu::Buffer,
    pub ranges: &'a wgpu::Buffer,
    pub point_range: &'a wgpu::Buffer,
    pub species: &'a wgpu::Buffer,
}

/// The GPU buffers of one packed draw list.
pub struct SphereBuffers {
    pub uniforms: wgpu::Buffer,
    pub bind_group: wgpu::BindGroup,
    pub points: u32,
}

impl SphereRaycastPass {
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sphere_raycast.wgsl"),
            source: wgpu::ShaderSource::Wgsl(
                shader_source(
                    device
                        .features()
                        .contains(wgpu::Features::SHADER_EARLY_DEPTH_TEST),
                )
                .into(),
            ),
        });
        // The points are read by the impostors' vertex stage, by the resolve of the
        // small-sphere raster (fragment) and by that raster (compute).
        let stages = wgpu::ShaderStages::VERTEX_FRAGMENT | wgpu::ShaderStages::COMPUTE;
        let storage = |binding: u32| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: stages,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sphere_raycast"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: stages,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(1),
                storage(2),
                storage(3),
                storage(4),
                storage(5),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sphere_raycast"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = sphere_pipeline(
            device,
            &pipeline_layout,
            &module,
            ("vs_main", "fs_main"),
            &colour_targets(&[COLOUR_FORMAT]),
        );
        let gbuffer = sphere_pipeline(
            device,
            &pipeline_layout,
            &module,
            ("vs_main", "fs_gbuffer"),
            &colour_targets(&[GBUFFER_FORMAT; 2]),
        );
        let small = device
            .features()
            .contains(SMALL_SPHERES_FEATURES)
            .then(|| SmallSpheres::new(device, &layout, &module));
        SphereRaycastPass {
            pipeline,
            gbuffer,
            layout,
            small,
        }
    }

    /// Uploads `packed` and makes the bind group.
    pub fn upload(&self, device: &wgpu::Device, packed: &PackedDraw) -> SphereBuffers {
        let storage = |label: &str, bytes: &[u8]| storage_buffer(device, label, bytes);
        let positions = storage("positions", bytemuck::cast_slice(&packed.positions));
        let attrs = storage("attrs", bytemuck::cast_slice(&packed.attrs));
        let ranges = storage("ranges", bytemuck::cast_slice(&packed.ranges));
        let point_range = storage("point_range", bytemuck::cast_slice(&packed.point_range));
        let species = storage("species", bytemuck::cast_slice(&packed.species));
        self.bind(
            device,
            &SphereInputs {
                positions: &positions,
                attrs: &attrs,
                ranges: &ranges,
                point_range: &point_range,
                species: &species,
            },
            packed.points(),
        )
    }

    /// Makes the bind group over existing buffers (e.g. a streaming pool) for `points`
    /// instances.
    pub fn bind(
        &self,
        device: &wgpu::Device,
        inputs: &SphereInputs<'_>,
        points: u32,
    ) -> SphereBuffers {
        let SphereInputs {
            positions,
            attrs,
            ranges,
            point_range,
            species,
        } = *inputs;
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame uniforms"),
            size: std::mem::size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sphere_raycast"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: positions.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: attrs.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: ranges.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: point_range.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: species.as_entire_binding(),
                },
            ],
        });
        SphereBuffers {
            uniforms,
            bind_group,
            points,
        }
    }

    /// Records the draw into `pass`.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, buffers: &SphereBuffers) {
        if buffers.points == 0 {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &buffers.bind_group, &[]);
        pass.draw(0..4, 0..buffers.points);
    }
}

/// Colour targets of `formats`, written whole without blending.
fn colour_targets(formats: &[wgpu::TextureFormat]) -> Vec<Option<wgpu::ColorTargetState>> {
    formats
        .iter()
        .map(|&format| {
            Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })
        })
        .collect()
}

/// A pipeline of the sphere pass: triangle strips from `(vertex, fragment)` of `module`
/// (a point's quad, or one full-screen triangle), depth-tested and written.
fn sphere_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    entries: (&str, &str),
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    let depth = wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(true),
        // Reversed depth (`Camera::depth_clip_from_view`): nearer is greater.
        depth_compare: Some(wgpu::CompareFunction::Greater),
        stencil: Default::default(),
        bias: Default::default(),
    };
    super::strip_pipeline(
        device,
        entries.1,
        layout,
        module,
        entries,
        targets,
        Some(depth),
    )
}

impl SmallSpheres {
    fn new(
        device: &wgpu::Device,
        points_layout: &wgpu::BindGroupLayout,
        sphere_module: &wgpu::ShaderModule,
    ) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("small_spheres.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SMALL_SPHERES_SHADER.into()),
        });
        let entry = |binding: u32, visibility, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        use wgpu::BufferBindingType as B;
        use wgpu::ShaderStages as S;
        let writable = B::Storage { read_only: false };
        let read = B::Storage { read_only: true };
        let raster_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("small spheres: raster"),
            entries: &[
                entry(0, S::COMPUTE, read),
                entry(1, S::COMPUTE, writable),
                entry(2, S::COMPUTE, writable),
                entry(3, S::COMPUTE, writable),
            ],
        });
        let draw_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("small spheres: draw"),
            entries: &[
                entry(0, S::FRAGMENT, read),
                entry(1, S::FRAGMENT, read),
                entry(2, S::VERTEX, read),
            ],
        });
        let raster = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("cs_small_spheres"),
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("small spheres: raster"),
                    bind_group_layouts: &[Some(points_layout), Some(&raster_layout)],
                    immediate_size: 0,
                }),
            ),
            module: &module,
            entry_point: Some("cs_small_spheres"),
            compilation_options: Default::default(),
            cache: None,
        });
        let draw_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("small spheres: draw"),
            bind_group_layouts: &[Some(points_layout), Some(&draw_layout)],
            immediate_size: 0,
        });
        let make = |entries, formats: &[wgpu::TextureFormat]| {
            sphere_pipeline(
                device,
                &draw_pipeline_layout,
                sphere_module,
                entries,
                &colour_targets(formats),
            )
        };
        let (colour, gbuffer) = (&[COLOUR_FORMAT][..], &[GBUFFER_FORMAT; 2][..]);
        use wgpu::util::DeviceExt;
        SmallSpheres {
            raster,
            resolve: make(("vs_fullscreen", "fs_resolve"), colour),
            listed: make(("vs_listed", "fs_main"), colour),
            resolve_gbuffer: make(("vs_fullscreen", "fs_resolve_gbuffer"), gbuffer),
            listed_gbuffer: make(("vs_listed", "fs_gbuffer"), gbuffer),
            args_init: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("small spheres: empty draw"),
                contents: bytemuck::cast_slice(&[4u32, 0, 0, 0]),
                usage: wgpu::BufferUsages::COPY_SRC,
            }),
            raster_layout,
            draw_layout,
        }
    }

    /// The buffers for drawing `points` points into a `width` × `height` image, or
    /// `None` when a per-pixel buffer of 8 bytes or the list of points would not fit one
    /// storage binding on this device (the impostors then draw every point). `reuse`,
    /// the buffers of an earlier frame, are kept when they are large enough (a frame
    /// costs no allocation then; the renderer keeps one set between frames).
    pub fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        [width, height]: [u32; 2],
        points: u32,
        reuse: Option<SmallSphereTargets>,
    ) -> Option<SmallSphereTargets> {
        let limits = device.limits();
        let max = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let visible_bytes = u64::from(width) * u64::from(height) * 8;
        let large_bytes = u64::from(points) * 4;
        if points == 0 || visible_bytes > max || large_bytes > max {
            return None;
        }
        let groups = points.div_ceil(64);
        let per_row = groups.min(limits.max_compute_workgroups_per_dimension.max(1));
        let rows = groups.div_ceil(per_row);
        if rows > limits.max_compute_workgroups_per_dimension {
            return None;
        }
        let uniforms = RasterUniforms {
            size: [width, height],
            points,
            max_side: SMALL_SPHERE_MAX_SIDE,
            row: per_row * 64,
            pad: [0; 3],
        };
        let mut targets = match reuse {
            Some(t) if t.visible.size() >= visible_bytes && t.large.size() >= large_bytes => t,
            _ => {
                // Room for a little more than asked, so that growing cuts and views
                // settle on one set of buffers.
                let grow = |bytes: u64| bytes.saturating_add(bytes / 4).min(max);
                self.allocate(device, grow(visible_bytes), grow(large_bytes))
            }
        };
        queue.write_buffer(&targets.uniforms, 0, bytemuck::bytes_of(&uniforms));
        targets.groups = [per_row, rows];
        targets.visible_bytes = visible_bytes;
        Some(targets)
    }

    fn allocate(
        &self,
        device: &wgpu::Device,
        visible_bytes: u64,
        large_bytes: u64,
    ) -> SmallSphereTargets {
        // Whole 8-byte pixels and 4-byte points.
        let (visible_bytes, large_bytes) = (visible_bytes & !7, large_bytes & !3);
        let buffer = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let uniforms = buffer(
            "small spheres: uniforms",
            std::mem::size_of::<RasterUniforms>() as u64,
            U::STORAGE | U::COPY_DST,
        );
        let visible = buffer(
            "small spheres: visible",
            visible_bytes,
            U::STORAGE | U::COPY_DST,
        );
        let large = buffer("small spheres: impostors", large_bytes, U::STORAGE);
        let args = buffer(
            "small spheres: draw",
            16,
            U::STORAGE | U::INDIRECT | U::COPY_DST | U::COPY_SRC,
        );
        let args_read = buffer(
            "small spheres: draw read-back",
            16,
            U::MAP_READ | U::COPY_DST,
        );
        let group = |layout: &wgpu::BindGroupLayout, buffers: &[&wgpu::Buffer]| {
            let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
                .iter()
                .enumerate()
                .map(|(k, b)| wgpu::BindGroupEntry {
                    binding: k as u32,
                    resource: b.as_entire_binding(),
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("small spheres"),
                layout,
                entries: &entries,
            })
        };
        let raster_group = group(&self.raster_layout, &[&uniforms, &visible, &large, &args]);
        let draw_group = group(&self.draw_layout, &[&uniforms, &visible, &large]);
        SmallSphereTargets {
            uniforms,
            visible,
            large,
            args,
            args_read,
            raster_group,
            draw_group,
            groups: [0, 0],
            visible_bytes: 0,
        }
    }

    /// Records the raster of one sample into `enc`: the pixels and the impostors' list
    /// emptied, then a compute pass of its own (with `timestamps` when given); the frame
    /// uniforms of `buffers` must hold the sample's projection.
    pub fn raster(
        &self,
        enc: &mut wgpu::CommandEncoder,
        buffers: &SphereBuffers,
        targets: &SmallSphereTargets,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        enc.clear_buffer(&targets.visible, 0, Some(targets.visible_bytes));
        enc.copy_buffer_to_buffer(&self.args_init, 0, &targets.args, 0, 16);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("small spheres"),
            timestamp_writes: timestamps,
        });
        pass.set_pipeline(&self.raster);
        pass.set_bind_group(0, &buffers.bind_group, &[]);
        pass.set_bind_group(1, &targets.raster_group, &[]);
        pass.dispatch_workgroups(targets.groups[0], targets.groups[1], 1);
    }

    /// Draws the raster's pixels, then the spheres it left to the impostors, into
    /// `pass`, whose targets are the sphere pass's (`Shaded`) or the S-NDF sampling's
    /// G-buffer (`GBuffer`: normal, albedo).
    pub fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        buffers: &SphereBuffers,
        targets: &SmallSphereTargets,
        output: SphereOutput,
    ) {
        let (resolve, listed) = match output {
            SphereOutput::Shaded => (&self.resolve, &self.listed),
            SphereOutput::GBuffer => (&self.resolve_gbuffer, &self.listed_gbuffer),
        };
        pass.set_bind_group(0, &buffers.bind_group, &[]);
        pass.set_bind_group(1, &targets.draw_group, &[]);
        pass.set_pipeline(resolve);
        pass.draw(0..3, 0..1);
        pass.set_pipeline(listed);
        pass.draw_indirect(&targets.args, 0);
    }
}

/// What the sphere pass writes: shaded colour, or the S-NDF sampling's G-buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SphereOutput {
    Shaded,
    GBuffer,
}

impl SmallSphereTargets {
    /// Bytes of GPU memory the targets hold.
    pub fn bytes(&self) -> u64 {
        self.uniforms.size() + self.visible.size() + self.large.size() + self.args.size()
    }

    /// Copies the impostors' indirect draw (4 words; the second is their count) to
    /// [`Self::draw_args_readback`].
    pub fn copy_draw_args(&self, enc: &mut wgpu::CommandEncoder) {
        enc.copy_buffer_to_buffer(&self.args, 0, &self.args_read, 0, 16);
    }

    /// The mappable copy of the impostors' indirect draw.
    pub fn draw_args_readback(&self) -> &wgpu::Buffer {
        &self.args_read
    }
}
