//! Fixed-size records of the `.mdlod` file, exactly as they lie on disk (little-endian).
//!
//! Each type is `#[repr(C)]` with no padding holes, so a section of the mapped file can
//! be viewed as a slice of it with `bytemuck`'s checked casts. Offsets in the comments
//! are byte offsets within the record; `FORMAT.md` lists the same tables.

use bytemuck::{Pod, Zeroable};

/// First eight bytes of every `.mdlod` file.
pub const MAGIC: [u8; 8] = *b"\x89MDLOD\r\n";

/// The format version this crate writes.
pub const FORMAT_VERSION: (u16, u16) = (1, 0);
/// The version of a file with per-particle radii (a RADIUS section), which readers of
/// version 1.0 open as well, drawing each particle at its species' radius.
pub const FORMAT_VERSION_RADII: (u16, u16) = (1, 1);

/// The version of files whose per-particle radii are quantized on a log scale (the
/// RADIUS_LOG section), or that keep more than one attribute (ATTRIBUTES).
pub const FORMAT_VERSION_1_2: (u16, u16) = (1, 2);

/// The most extra attributes a file keeps (the metadata's `attributes`).
pub const MAX_EXTRA_ATTRIBUTES: usize = 64;

/// The major versions this crate reads: files whose major version lies in this range
/// are accepted whatever their minor version (minor versions only add sections or JSON
/// fields, which readers skip).
pub const READABLE_MAJOR: std::ops::RangeInclusive<u16> = 1..=1;

/// Every section starts at a multiple of this many bytes.
pub const SECTION_ALIGN: u64 = 64;

/// Size of the file header.
pub const HEADER_SIZE: usize = 64;

/// The file header, at offset 0.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Eq)]
pub struct Header {
    /// 0: [`MAGIC`].
    pub magic: [u8; 8],
    /// 8: major version; readers refuse majors outside their range.
    pub version_major: u16,
    /// 10: minor version; additions only.
    pub version_minor: u16,
    /// 12: reserved, 0.
    pub flags: u32,
    /// 16: number of entries in the section table.
    pub section_count: u32,
    /// 20: bits per quantized coordinate in every POSITIONS section: 8 or 16.
    pub position_bits: u32,
    /// 24: byte offset of the section table (a multiple of 64).
    pub section_table_offset: u64,
    /// 32: total file size in bytes.
    pub file_size: u64,
    /// 40: XXH3-64 (seed 0) of the section table bytes.
    pub section_table_checksum: u64,
    /// 48: reserved, 0.
    pub reserved: u64,
    /// 56: XXH3-64 (seed 0) of header bytes 0..56.
    pub header_checksum: u64,
}

/// One entry of the section table.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Eq)]
pub struct SectionEntry {
    /// 0: a [`SectionKind`] code; unknown codes are skipped by readers.
    pub kind: u32,
    /// 4: hierarchy level the section belongs to (0 where not per-level).
    pub level: u32,
    /// 8: byte offset from the start of the file (a multiple of 64).
    pub offset: u64,
    /// 16: length in bytes (padding after it is not included).
    pub length: u64,
    /// 24: XXH3-64 (seed 0) of the section's `length` bytes.
    pub checksum: u64,
}

/// What a section holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SectionKind {
    /// UTF-8 JSON, see [`crate::meta::Metadata`].
    Metadata = 1,
    /// One [`LevelRecord`] per level, coarsest first.
    Levels = 2,
    /// All [`NodeRecord`]s, level by level.
    Nodes = 3,
    /// Quantized positions of one level (`level` ≥ 1): 3 × u8 or 3 × u16 per point.
    Positions = 4,
    /// u16 species index per particle of the finest level.
    Species = 5,
    /// u16 quantized scalar attribute per particle of the finest level.
    Attribute = 6,
    /// u16 quantized radius per particle of the finest level (version 1.1).
    Radius = 7,
    /// u16 radius per particle of the finest level quantized on a log scale (version 1.2):
    /// for radii spanning decades (smoothing lengths), which linear steps cannot keep.
    RadiusLog = 8,
    /// The extra per-particle attributes (version 1.2): for each of the metadata's
    /// `attributes` in turn, a u16 per particle of the finest level, quantized as
    /// ATTRIBUTE's.
    Attributes = 9,
    /// The extra attributes' node means (version 1.2): for each of the metadata's
    /// `attributes` in turn, an f32 per node (the area-weighted mean of its particles'
    /// values), as [`NodeRecord::attribute`] holds the first attribute's.
    NodeAttributes = 10,
}

impl SectionKind {
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            1 => Self::Metadata,
            2 => Self::Levels,
            3 => Self::Nodes,
            4 => Self::Positions,
            5 => Self::Species,
            6 => Self::Attribute,
            7 => Self::Radius,
            8 => Self::RadiusLog,
            9 => Self::Attributes,
            10 => Self::NodeAttributes,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Metadata => "METADATA",
            Self::Levels => "LEVELS",
            Self::Nodes => "NODES",
            Self::Positions => "POSITIONS",
            Self::Species => "SPECIES",
            Self::Attribute => "ATTRIBUTE",
            Self::Radius => "RADIUS",
            Self::RadiusLog => "RADIUS_LOG",
            Self::Attributes => "ATTRIBUTES",
            Self::NodeAttributes => "NODE_ATTRIBUTES",
        }
    }
}

/// One level of the hierarchy. Level 0 holds the single top node; the last level holds
/// the particles themselves.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Eq)]
pub struct LevelRecord {
    /// 0: number of points on this level.
    pub point_count: u64,
    /// 8: index of this level's first node in the node table (the node count before it).
    /// The points of every level but the last are nodes, in the same order.
    pub node_first: u64,
    /// 16: reserved, 0.
    pub reserved: [u64; 2],
}

/// One cluster: a point of a level above the finest, with its children on the next level.
///
/// Points on level `l + 1` are ordered so that the children of every level-`l` node are
/// contiguous and in the order of their parents; hence every node's descendants on any
/// deeper level are contiguous too.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct NodeRecord {
    /// 0: the representative's position: the radius-weighted centroid of its children.
    /// Also the base of the quantized positions this node encodes.
    pub centroid: [f32; 3],
    /// 12: the representative's radius (Hopf et al. Eq. 2, in radii).
    pub radius: f32,
    /// 16: per-axis step of the quantized positions this node encodes (0 when it
    /// encodes none): `position = centroid + quant_scale * (q - H)`.
    pub quant_scale: [f32; 3],
    /// 28: Σ r² over the particles below: flux = π · area_sum · colour (Eq. 1).
    pub area_sum: f32,
    /// 32: lower corner of the box bounding every particle sphere below.
    pub bounds_min: [f32; 3],
    /// 44: area-weighted mean of the scalar attribute below (0 without attribute).
    pub attribute: f32,
    /// 48: upper corner of the bounding box.
    pub bounds_max: [f32; 3],
    /// 60: area-weighted mean linear RGB albedo below, RGBA8 (A = 255), R in the low byte.
    pub colour: u32,
    /// 64: index of the first child among the points of level `level + 1`.
    pub child_first: u32,
    /// 68: number of children (≥ 1).
    pub child_count: u32,
    /// 72: index of the first descendant among the points of level `point_level`.
    pub point_first: u32,
    /// 76: number of descendants on level `point_level`.
    pub point_count: u32,
    /// 80: node index of the parent (`u32::MAX` for the top node).
    pub parent: u32,
    /// 84: node index whose `centroid` and `quant_scale` encode this node's point range.
    pub quant_node: u32,
    /// 88: root-mean-square distance of the particles below from `centroid`.
    pub rms_radius: f32,
    /// 92: this node's level.
    pub level: u8,
    /// 93: the level of this node's point range: `min(level + delta_n, last level)`.
    pub point_level: u8,
    /// 94: the species with the largest area below (a hint for colouring by species).
    pub species: u16,
}

const _: () = assert!(std::mem::size_of::<Header>() == HEADER_SIZE);
const _: () = assert!(std::mem::size_of::<SectionEntry>() == 32);
const _: () = assert!(std::mem::size_of::<LevelRecord>() == 32);
const _: () = assert!(std::mem::size_of::<NodeRecord>() == 96);

impl NodeRecord {
    /// The RGB albedo in [0, 1].
    pub fn colour_rgb(&self) -> [f32; 3] {
        let c = self.colour.to_le_bytes();
        [c[0], c[1], c[2]].map(|v| f32::from(v) / 255.0)
    }
}

/// Packs a linear RGB albedo in [0, 1] as RGBA8 with alpha 255.
pub fn pack_colour(rgb: [f32; 3]) -> u32 {
    let q = rgb.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
    u32::from_le_bytes([q[0], q[1], q[2], 255])
}

/// Rounds `offset` up to the next multiple of [`SECTION_ALIGN`]; `None` on overflow.
pub fn align_up(offset: u64) -> Option<u64> {
    offset
        .checked_add(SECTION_ALIGN - 1)
        .map(|v| v / SECTION_ALIGN * SECTION_ALIGN)
}
