//! Choosing what to draw: a cut through the hierarchy by projected size.
//!
//! How it works. Every point of the file is either a node (a cluster, drawn as one
//! sphere: its *representative*, with the node's radius and colour) or a particle (a
//! point of the finest level). The cut is a set of points on mixed levels such that every
//! particle inside the view is covered by exactly one drawn ancestor-or-self.
//!
//! 1. Start with the top node drawn as its own representative.
//! 2. Keep the drawn nodes in a priority queue by *projected size*: the diameter in
//!    pixels of the sphere around the node's bounding box, at the sphere's nearest depth
//!    (perspective) or at the fixed scale (orthographic); a sphere reaching the near
//!    plane counts as infinitely large. The box bounds every particle sphere below the
//!    node, so drawing the node's representative instead of its particles moves nothing
//!    by more than that size.
//! 3. Pop the largest. If it is at most `error_px`, stop: every node still drawn is
//!    small enough. Otherwise *open* it: its representative is replaced by its children
//!    (nodes of the next level, each drawn as its own representative and queued in
//!    turn, or particles, which are final). Children whose bounding box lies outside the
//!    view frustum are culled with their whole subtree; particle children are kept
//!    whenever their parent is visible (they are culled with their parent's box). Points
//!    drawn as kernels wider than their spheres (the density volume,
//!    [`TraversalSettings::support_scale`]) are culled by their boxes grown by the
//!    kernels' reach, so that a node just outside the view still adds density inside it.
//! 4. Opening a node changes the number of drawn points by `visible children − 1`. If
//!    that would exceed `budget_points`, refinement stops there: largest first means
//!    that what is left is uniformly as fine as the budget allows, and the size of that
//!    node is reported as the error actually achieved.
//!
//! The result is emitted per opened node: the children it draws (those not opened and
//! not culled) as maximal runs of consecutive points. Children of one node are
//! contiguous on their level and share one encoding node (the ancestor on level
//! `max(0, level − δn)`), so each run is one [`DrawRange`] decoded with one base and
//! scale; when no child of a node is opened or culled, the run is the node's whole
//! child range, i.e. with δn = 1 exactly its stored `point_first`/`point_count` range.
//! With δn > 1 the cut still refines one level at a time (through `child_first` /
//! `child_count`), so the choice of points is as fine-grained as with δn = 1; δn only
//! changes which ancestor's base and scale decode a run (`quant_node`), and a node's
//! stored δn-deep `point_first`/`point_count` range is not needed here.
//! A top node that is never opened is drawn as a range of level 0 (its centroid).
//! Ranges come out ordered by opened node index, so by level and position in the file.
//!
//! With occlusion culling ([`TraversalSettings::occlusion`], on by default) the same
//! cut is walked *nearest first* instead: a node whose box is hidden behind the spheres
//! already committed (see [`crate::occlusion`]) is dropped with its whole subtree; a node
//! small enough is committed as its representative; any other is opened. When a node is
//! opened, its particle children and its node children small enough to be drawn are
//! committed at once, each after a hidden test of the one sphere drawn for it (its
//! view-aligned box at the sphere's nearest depth: much tighter than its node's box
//! grown by the radius); only the larger
//! children go into the queue. Which particles of a node are drawn is kept as a 64-bit
//! mask (nodes of more than 64 particles draw them all), so the cut's particle ranges
//! are the runs of drawn particles. Every commitment is recorded in the occlusion buffer, so what is
//! behind it is culled as the walk goes deeper. Without a budget the result is exactly
//! the cut above minus hidden subtrees, and no pixel changes. The budget counts
//! committed points; when they exceed it the walk starts over with the error 1.5×
//! coarser (reported in [`DrawList::restarts`] and as `budget_limited`), so a
//! budget-limited cut is uniformly coarser rather than fine in front and coarse behind.
//!
//! [`traverse`] runs that walk on every core: the image is cut into tiles of 128×128
//! pixels, each walked with an occlusion buffer of its own pixels, visiting only the
//! nodes whose boxes reach them. Opening and drawing depend on projected size alone, so
//! the tiles agree on them; the cut is the union of what the tiles opened and drew, and
//! a node is left out when no tile can see it. Nodes on tile borders are visited by each
//! tile they reach (about a tenth more work). The tiles do not depend on the thread
//! count, so neither does the cut. Streaming ([`traverse_with`]) walks the whole image
//! at once, because the residency answers in the order it is asked.
//!
//! Hidden species and values and clip planes ([`TraversalSettings::hidden`],
//! [`TraversalSettings::clip`]): a cluster of hidden species only, or whose box (grown
//! by the quantization error) lies wholly beyond a plane, is culled with its subtree; one
//! holding both kinds, or across a plane, is opened whatever its size (without occlusion
//! after every larger node, so that a budget refines what is large on screen first),
//! down to particles, each left out by its species, its attribute value or its decoded
//! centre. The cut then draws exactly the particles kept and clusters of them only. With
//! occlusion, what is left out neither draws nor hides anything behind it: only the
//! spheres drawn go into the occlusion buffer, so the bulk behind a cross-section's face
//! or behind the atoms a figure keeps is culled as without hiding.
//!
//! Streaming plugs in through [`Residency`]: a node whose children's data are not on the
//! GPU is not opened but stays drawn (so a missing subtree is drawn by its nearest
//! resident ancestor) and refinement continues with the other nodes; the residency
//! records what it was asked for, largest first.
//!
//! Node records are read only once checked: a file of more than
//! [`mdlod_format::reader::EAGER_NODES`] nodes has its top levels checked on open and
//! the rest in blocks as walks reach them ([`MdlodFile::check_children`] before a node's
//! children are read). A node whose children's records are corrupt is drawn as its
//! representative, and the error is kept for the caller to report
//! ([`MdlodFile::node_error`]).
//!
//! This is a pure function of the camera, the file and the settings: no GPU involved.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use glam::{Mat4, Vec3};
use mdlod_format::reader::{HiddenSet, HiddenTest, BELOW_IN, BELOW_OUT};
use mdlod_format::{quantize, MdlodFile, NodeRecord};

use crate::camera::{Camera, Projection};
use crate::occlusion::{OcclusionBuffer, OcclusionMode};

/// What the cut must honour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraversalSettings {
    /// Image size in pixels (width, height); sizes are measured in its pixels.
    pub viewport: [u32; 2],
    /// Largest projected size (pixels) of a node drawn as its representative.
    pub error_px: f32,
    /// Most points (spheres) to draw; at least 1 is always drawn when anything is visible.
    pub budget_points: u64,
    /// Occlusion culling (see [`crate::occlusion`]); match it to the samples per pixel.
    pub occlusion: OcclusionMode,
    /// Points drawn as kernels reaching this many times their radius (the density
    /// volume's `kernel_scale`; see [`Projector::with_support`]); 0 for spheres and
    /// splats, whose node boxes bound what they draw.
    pub support_scale: f32,
    /// Particles drawn as nothing: of some species (bit `s` for species index `s`), or
    /// of attribute values in some ranges (`--hide-attribute`). A cluster of them only
    /// is culled, and one holding them and others is opened (its representative would
    /// draw them), down to particles where the budget allows
    /// ([`MdlodFile::hidden_below`]). With occlusion culling, only what is drawn hides
    /// what is behind it.
    pub hidden: HiddenSet,
    /// Planes that cut the data away (OVITO's Slice): particles whose centres lie beyond
    /// any are left out, clusters wholly beyond are culled, and clusters across a plane
    /// are opened down to particles where the budget allows, as for hidden species.
    pub clip: ClipPlanes,
}

/// At most this many clip planes cut a view.
pub const MAX_CLIP_PLANES: usize = 6;

/// Half-spaces `n·p ≤ d` that keep a particle whose centre `p` lies inside every one
/// ([`TraversalSettings::clip`]); none keeps everything.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClipPlanes {
    planes: [[f32; 4]; MAX_CLIP_PLANES],
    count: usize,
    /// How far beyond a plane (in units of its normal's length) a decoded centre is
    /// still kept ([`ClipPlanes::for_file`]).
    slack: f32,
}

/// Where a box lies against clip planes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipSide {
    /// Inside every half-space: nothing in it is cut away.
    Kept,
    /// Wholly beyond one plane: everything in it is cut away.
    Beyond,
    /// Across a plane: some of it may be cut away.
    Across,
}

impl ClipPlanes {
    /// Planes `[nx, ny, nz, d]`, each keeping `n·p ≤ d`: at most [`MAX_CLIP_PLANES`],
    /// finite, with a non-zero normal.
    pub fn new(planes: &[[f32; 4]]) -> Result<ClipPlanes, String> {
        if planes.len() > MAX_CLIP_PLANES {
            return Err(format!(
                "{} clip planes: at most {MAX_CLIP_PLANES} cut one view",
                planes.len()
            ));
        }
        let mut out = ClipPlanes::default();
        for p in planes {
            if p.iter().any(|v| !v.is_finite()) || p[..3].iter().all(|&v| v == 0.0) {
                return Err(format!(
                    "clip plane {p:?}: needs finite numbers and a non-zero normal nx,ny,nz"
                ));
            }
            out.planes[out.count] = *p;
            out.count += 1;
        }
        Ok(out)
    }

    pub fn planes(&self) -> &[[f32; 4]] {
        &self.planes[..self.count]
    }

    /// The planes as they cut `file`'s particles: a centre within the file's largest
    /// position error (its quantization's, recorded when it was built) beyond a plane
    /// is kept, so that atoms of a lattice plane a clip plane lies on (`--clip 1,0,0,30`
    /// through a crystal's x = 30 layer) are all kept, as their exact positions are,
    /// not about half of them as their decoded ones fall either side.
    pub fn for_file(self, file: &MdlodFile) -> ClipPlanes {
        let e = file.metadata().max_position_error;
        ClipPlanes {
            slack: if e.is_finite() && e > 0.0 {
                e as f32
            } else {
                0.0
            },
            ..self
        }
    }

    /// `n·p ≤ d` of plane `c`, with the slack.
    fn limit(&self, c: &[f32; 4]) -> f32 {
        c[3] + self.slack * Vec3::new(c[0], c[1], c[2]).length()
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The particle centred at `p` is kept.
    pub fn keeps(&self, p: Vec3) -> bool {
        self.planes()
            .iter()
            .all(|c| Vec3::new(c[0], c[1], c[2]).dot(p) <= self.limit(c))
    }

    /// Where the box `min..max`, grown by `grow` on every side, lies.
    pub fn side(&self, min: Vec3, max: Vec3, grow: f32) -> ClipSide {
        let mut side = ClipSide::Kept;
        for c in self.planes() {
            let n = Vec3::new(c[0], c[1], c[2]);
            // The box's smallest and largest n·p: each axis at its end along n.
            let lo = n.min(Vec3::ZERO).dot(max) + n.max(Vec3::ZERO).dot(min);
            let hi = n.max(Vec3::ZERO).dot(max) + n.min(Vec3::ZERO).dot(min);
            let g = n.length() * grow;
            if lo - g > self.limit(c) {
                return ClipSide::Beyond;
            }
            if hi + g > self.limit(c) {
                side = ClipSide::Across;
            }
        }
        side
    }
}

impl Default for TraversalSettings {
    fn default() -> Self {
        TraversalSettings {
            viewport: [1280, 720],
            error_px: 1.0,
            budget_points: 4_000_000,
            occlusion: OcclusionMode::PixelCentres,
            support_scale: 0.0,
            hidden: HiddenSet::default(),
            clip: ClipPlanes::default(),
        }
    }
}

/// A run of consecutive points of one level, drawn with one base and scale.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DrawRange {
    /// The level of the points. Level 0 is the top node itself, drawn at its centroid.
    pub level: u8,
    /// First point index on `level`.
    pub first: u32,
    /// Number of points.
    pub count: u32,
    /// Node whose `centroid` and `quant_scale` decode the points' positions
    /// (for level 0: node 0, whose centroid is the position).
    pub quant_node: u32,
}

/// The cut: what to draw, and how it was chosen.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DrawList {
    pub ranges: Vec<DrawRange>,
    /// Points drawn (spheres): `particles + representatives`.
    pub points: u64,
    /// Particles (finest-level points) drawn.
    pub particles: u64,
    /// Node representatives drawn.
    pub representatives: u64,
    /// Nodes opened (replaced by their children).
    pub opened_nodes: u64,
    /// Nodes whose subtree was culled by the view frustum.
    pub culled_nodes: u64,
    /// Largest projected size (px) of a drawn representative: the error achieved
    /// (0 when only particles are drawn).
    pub error_px: f32,
    /// True when the budget stopped refinement before `error_px` was reached.
    pub budget_limited: bool,
    /// Nodes that should have been opened but whose children were not resident
    /// (streaming); they are drawn as their representatives.
    pub deferred_nodes: u64,
    /// Nodes left out by occlusion culling: no sample of the image sees them in front of
    /// spheres already drawn, because those hide them or because they fall between the
    /// samples (pixel centres) altogether; the two are not told apart.
    pub occluded_nodes: u64,
    /// Particles left out likewise: hidden by spheres already drawn, or between pixel
    /// centres (a sphere narrower than a pixel whose disk holds none); tested one by one
    /// below nodes of at most 64 children.
    pub occluded_particles: u64,
    /// Particles of hidden species ([`TraversalSettings::hidden_species`]) left out of
    /// the opened nodes' runs.
    pub hidden_particles: u64,
    /// Particles cut away by the clip planes ([`TraversalSettings::clip`]) from the
    /// opened nodes' runs (those of hidden species counted as hidden).
    pub clipped_particles: u64,
    /// Clusters drawn across a clip plane: the budget (or a node not yet resident)
    /// stopped their refinement.
    pub across_drawn: u64,
    /// Clusters drawn that still hold hidden species' particles: the budget (or a node
    /// not yet resident) stopped their refinement.
    pub mixed_drawn: u64,
    /// Times the occlusion traversal started over with a coarser error to meet the
    /// budget.
    pub restarts: u32,
}

impl DrawList {
    /// The ranges cut into consecutive batches of at most `max_points` points and
    /// `max_ranges` ranges each (a range split where a batch fills up), in draw order:
    /// the points of batch 0, then those of batch 1, and so on are exactly the list's.
    /// Each batch has its ranges and its `points`; the other counts describe the whole
    /// cut and are left at zero. An empty list gives one empty batch.
    pub fn batches(&self, max_points: u32, max_ranges: usize) -> Vec<DrawList> {
        let (max_points, max_ranges) = (max_points.max(1), max_ranges.max(1));
        let full = |b: &DrawList| b.points == u64::from(max_points) || b.ranges.len() == max_ranges;
        let mut out = vec![DrawList::default()];
        for r in &self.ranges {
            let (mut first, mut left) = (r.first, r.count);
            while left > 0 {
                if out.last().is_some_and(full) {
                    out.push(DrawList::default());
                }
                let Some(b) = out.last_mut() else { break };
                let room = max_points - b.points as u32;
                let count = left.min(room);
                b.ranges.push(DrawRange { first, count, ..*r });
                b.points += u64::from(count);
                first += count;
                left -= count;
            }
        }
        out
    }
}

#[derive(Clone, Copy, PartialEq)]
struct Size(f32);
impl Eq for Size {}
impl PartialOrd for Size {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Size {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// Projects node bounds for the size test and the frustum test.
pub struct Projector {
    view_from_world: Mat4,
    planes: [glam::Vec4; 6],
    projection: Projection,
    near: f32,
    /// Pixels per world unit at depth 1 (perspective) or everywhere (orthographic).
    scale: f32,
    /// See [`Self::with_support`].
    support_scale: f32,
    support_floor: f32,
}

impl Projector {
    pub fn new(camera: &Camera, viewport: [u32; 2]) -> Self {
        Projector {
            view_from_world: camera.view_from_world(),
            planes: camera.frustum(viewport),
            projection: camera.projection,
            near: camera.near,
            scale: camera.pixels_per_world(1.0, viewport[1]),
            support_scale: 0.0,
            support_floor: 0.0,
        }
    }

    /// A projector whose frustum test keeps a node while the kernels of its subtree may
    /// reach into the view: its box grown by `support_scale` times the larger of its flux
    /// radius `√area_sum` (at least its radius) and `support_floor` (the file's largest
    /// species radius), which bounds every kernel below it: area sums only grow up the
    /// hierarchy, and a representative's support `(r_ref ρ²)^{1/3}` is at most the larger
    /// of `ρ` and `r_ref` (see `density::DensityPoint::support`). A node just outside the
    /// view still adds density inside it.
    pub fn with_support(
        camera: &Camera,
        viewport: [u32; 2],
        support_scale: f32,
        support_floor: f32,
    ) -> Self {
        let finite = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
        Projector {
            support_scale: finite(support_scale),
            support_floor: finite(support_floor),
            ..Self::new(camera, viewport)
        }
    }

    /// The node's box as the frustum tests see it.
    fn culled_box(&self, n: &NodeRecord) -> (Vec3, Vec3) {
        let (min, max) = (Vec3::from(n.bounds_min), Vec3::from(n.bounds_max));
        if self.support_scale == 0.0 {
            return (min, max);
        }
        let reach = self.support_scale
            * n.area_sum
                .max(0.0)
                .sqrt()
                .max(n.radius)
                .max(self.support_floor);
        if !reach.is_finite() {
            // (Checked records hold finite values; nothing to grow by otherwise.)
            return (min, max);
        }
        (min - Vec3::splat(reach), max + Vec3::splat(reach))
    }

    /// Diameter in pixels of the sphere around the node's bounding box.
    pub fn size_px(&self, n: &NodeRecord) -> f32 {
        self.size_and_near(n).0
    }

    /// [`Self::size_px`] and [`Self::near_depth`] together, from one transform of the
    /// box's centre.
    pub fn size_and_near(&self, n: &NodeRecord) -> (f32, f32) {
        let (min, max) = (Vec3::from(n.bounds_min), Vec3::from(n.bounds_max));
        let r = half_diagonal(max - min);
        let depth = -self
            .view_from_world
            .transform_point3(min * 0.5 + max * 0.5)
            .z;
        let nearest = depth - r;
        let size = match self.projection {
            Projection::Orthographic => 2.0 * r * self.scale,
            Projection::Perspective if nearest <= self.near.max(0.0) => f32::INFINITY,
            Projection::Perspective => 2.0 * r * self.scale / nearest,
        };
        (size, nearest)
    }

    /// Distance along the view direction to the near side of the sphere around the
    /// node's bounding box: the order in which the occlusion traversal visits nodes.
    pub fn near_depth(&self, n: &NodeRecord) -> f32 {
        self.size_and_near(n).1
    }

    /// True when the node's bounding box may intersect the view frustum.
    pub fn visible(&self, n: &NodeRecord) -> bool {
        let (min, max) = self.culled_box(n);
        Camera::box_in_frustum(&self.planes, min, max)
    }

    /// [`Self::visible`] as `Some`, holding whether the box lies wholly inside the
    /// frustum, so that the node's descendants (whose boxes lie in its box) need no test.
    pub fn frustum(&self, n: &NodeRecord) -> Option<bool> {
        let (min, max) = self.culled_box(n);
        Camera::box_against_frustum(&self.planes, min, max)
    }
}

/// Half the length of a box's diagonal `e`: in double precision where its square
/// overflows single precision (boxes past 1.8·10^19: stars in metres).
#[inline]
fn half_diagonal(e: Vec3) -> f32 {
    let l2 = e.length_squared();
    if l2.is_finite() {
        l2.sqrt() * 0.5
    } else {
        (e.as_dvec3().length() * 0.5) as f32
    }
}

/// The radius a node's representative sphere is drawn with: the *coverage radius*
/// `√area_sum`, whose disk has the projected area of all the particle disks below
/// (Eq. 1's flux carried by the size, the colour kept), capped by the size of the
/// node's box (`½ ∛(extent_x · extent_y · extent_z)`, so that a compact cluster is not
/// drawn larger than itself) and never below the Eq. 2 radius stored in the file.
///
/// Why not Eq. 2 alone: that radius barely exceeds the largest child's, so a coarse cut
/// of a solid is a sparse cloud of small spheres through which deeper ones show, which
/// both changes the picture (the solid looks porous) and defeats occlusion culling.
/// Spheres of equal flux keep, on average, the same covered area per unit depth as the
/// particles they stand for. All three terms only grow up the hierarchy, so a node's
/// radius bounds every representative radius in its subtree.
pub fn representative_radius(n: &NodeRecord) -> f32 {
    let e = Vec3::from(n.bounds_max) - Vec3::from(n.bounds_min);
    let volume = e.x.max(0.0) * e.y.max(0.0) * e.z.max(0.0);
    let coverage = n.area_sum.max(0.0).sqrt();
    // The cap's cube root only when the cap may be the smaller (coverage³ > volume / 8).
    let smaller = if 8.0 * coverage * coverage * coverage <= volume {
        coverage
    } else {
        coverage.min(0.5 * volume.cbrt())
    };
    let r = smaller.max(n.radius);
    if r.is_finite() {
        r
    } else {
        n.radius
    }
}

/// Per-node marks of one traversal: a byte per node, zero-initialised lazily by the OS
/// (only the pages of visited nodes are touched), plus the list of opened nodes.
struct Marks {
    state: Vec<u8>,
    open: Vec<u32>,
}

const OPENED: u8 = 1;
/// Drawn as its representative (the occlusion traversal records what it draws; the
/// largest-first cut draws every child of an opened node that is neither opened nor
/// outside the frustum).
const DRAWN: u8 = 2;

impl Marks {
    fn new(nodes: usize) -> Self {
        Marks {
            state: vec![0; nodes],
            open: Vec::new(),
        }
    }

    fn open(&mut self, id: u32) {
        self.state[id as usize] = OPENED;
        self.open.push(id);
    }

    fn commit(&mut self, id: u32) {
        self.state[id as usize] = DRAWN;
    }

    fn get(&self, id: u32) -> u8 {
        self.state[id as usize]
    }
}

/// The node that encodes the positions of the children of node `parent`.
fn children_encoder(file: &MdlodFile, parent: usize) -> usize {
    let nodes = file.nodes();
    let child_level = usize::from(nodes[parent].level) + 1;
    let ql = child_level.saturating_sub(file.delta_n());
    let mut n = parent;
    while usize::from(nodes[n].level) > ql {
        n = nodes[n].parent as usize;
    }
    n
}

/// Whether a node's children can be drawn now (streaming: are their data on the GPU?).
pub trait Residency {
    /// Called for node `id` (of projected size `size_px`) just before it would be
    /// opened, after the budget check. `false` keeps the node drawn as its
    /// representative (a non-resident subtree is drawn by its nearest resident
    /// ancestor); an implementation may then request the data, most wanted (largest)
    /// first. `true` means the children may be drawn in this frame.
    fn can_open(&mut self, file: &MdlodFile, id: u32, size_px: f32) -> bool;

    /// The traversal starts over (with a coarser error): forget this pass's requests.
    fn restart(&mut self) {}

    /// True when the answers of [`Self::can_open`] do not depend on the order it is
    /// asked in (a residency that records no state between questions), so a cut no budget
    /// limits may visit the nodes in any order.
    fn order_free(&self) -> bool {
        false
    }
}

/// Everything is resident (the whole file is at hand).
pub struct AllResident;

impl Residency for AllResident {
    fn can_open(&mut self, _file: &MdlodFile, _id: u32, _size_px: f32) -> bool {
        true
    }

    fn order_free(&self) -> bool {
        true
    }
}

/// Whether a node's children can be drawn now, asked by every tile of the parallel
/// traversal at once ([`traverse_shared`]); unlike [`Residency`] it records nothing.
pub trait SharedResidency: Sync {
    /// True when the children of node `id` may be drawn in this frame.
    fn resident(&self, file: &MdlodFile, id: u32) -> bool;

    /// Whether the caller wants the nodes asked about ([`traverse_shared`]'s list).
    fn wants_asked(&self) -> bool {
        true
    }
}

impl SharedResidency for AllResident {
    fn resident(&self, _file: &MdlodFile, _id: u32) -> bool {
        true
    }

    fn wants_asked(&self) -> bool {
        false
    }
}

/// A tile's [`Residency`]: answers from the shared one and remembers what it was asked.
struct TileResidency<'a> {
    shared: &'a dyn SharedResidency,
    asked: Vec<(u32, f32)>,
}

impl Residency for TileResidency<'_> {
    fn can_open(&mut self, file: &MdlodFile, id: u32, size_px: f32) -> bool {
        if self.shared.wants_asked() {
            self.asked.push((id, size_px));
        }
        self.shared.resident(file, id)
    }

    fn restart(&mut self) {
        self.asked.clear();
    }

    /// The shared residency answers without state, and the nodes asked are sorted by
    /// size afterwards ([`largest_first_once`]).
    fn order_free(&self) -> bool {
        true
    }
}

/// Chooses the cut for `camera` (see the module docs). Node records are checked as the
/// walk reaches them ([`MdlodFile::check_children`]); a node whose children fail is drawn
/// as its representative and the failure kept in [`MdlodFile::node_error`], which callers
/// report.
pub fn traverse(camera: &Camera, file: &MdlodFile, settings: &TraversalSettings) -> DrawList {
    traverse_shared(camera, file, settings, &AllResident).0
}

/// [`traverse`] where opening a node also needs `residency`'s consent, on every core
/// with occlusion culling (in one pass without). A refused node stays drawn as its
/// representative and refinement goes on with the others. Also returns the nodes the
/// cut asked to open, each once with its projected size, largest first (a streaming
/// pool requests the missing ones in that order), unless the residency does not want
/// them.
pub fn traverse_shared(
    camera: &Camera,
    file: &MdlodFile,
    settings: &TraversalSettings,
    residency: &dyn SharedResidency,
) -> (DrawList, Vec<(u32, f32)>) {
    if settings.occlusion == OcclusionMode::Off || settings.viewport.contains(&0) {
        let mut tile = TileResidency {
            shared: residency,
            asked: Vec::new(),
        };
        let list = traverse_with(camera, file, settings, &mut tile);
        (list, largest_first_once(tile.asked))
    } else {
        traverse_tiled(camera, file, settings, residency)
    }
}

/// Nodes a traversal asked to open, with their projected sizes.
pub type Asked = Vec<(u32, f32)>;

/// Each asked node once (the largest size it was asked with), largest first, ties by id.
fn largest_first_once(mut asked: Vec<(u32, f32)>) -> Vec<(u32, f32)> {
    asked.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)));
    asked.dedup_by_key(|a| a.0);
    asked.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    asked
}

/// [`traverse`] where opening a node also needs `residency`'s consent; a refused node
/// stays drawn and refinement goes on with the others.
pub fn traverse_with(
    camera: &Camera,
    file: &MdlodFile,
    settings: &TraversalSettings,
    residency: &mut dyn Residency,
) -> DrawList {
    if settings.occlusion != OcclusionMode::Off {
        let proj = Projector::with_support(
            camera,
            settings.viewport,
            settings.support_scale,
            file.max_particle_radius(),
        );
        if !proj.visible(&file.nodes()[0]) || all_left_out(file, settings) {
            return DrawList {
                culled_nodes: 1,
                ..Default::default()
            };
        }
        let mut error_px = settings.error_px;
        for attempt in 0..MAX_RESTARTS {
            let Some(mut buffer) =
                OcclusionBuffer::new(camera, settings.viewport, settings.occlusion)
            else {
                break;
            };
            if let Some(d) = front_to_back(
                camera,
                file,
                settings,
                error_px,
                residency,
                &mut buffer,
                None,
            ) {
                let deferred = d.deferred;
                let mut list = cut_of(file, &proj, settings, vec![d]);
                list.deferred_nodes = deferred;
                list.restarts = attempt;
                list.budget_limited = attempt > 0;
                return list;
            }
            residency.restart();
            // Coarser than the whole data set on screen, only clusters that must be opened
            // (mixed, across a plane) are: a coarser error changes nothing more.
            if error_px > proj.size_px(&file.nodes()[0]) {
                break;
            }
            error_px = coarser(error_px);
        }
    }
    largest_first(camera, file, settings, residency)
}

/// The cut that occlusion passes (the whole image's, or its tiles') decided together:
/// what any of them opened, drew, or kept of an opened node's particles.
fn cut_of(
    file: &MdlodFile,
    proj: &Projector,
    settings: &TraversalSettings,
    passes: Vec<Decisions>,
) -> DrawList {
    let mut marks = Marks::new(file.nodes().len());
    let mut achieved = 0.0f32;
    for d in &passes {
        achieved = achieved.max(d.achieved);
        for &id in &d.committed {
            marks.commit(id);
        }
    }
    for d in &passes {
        for &id in &d.opened {
            if marks.get(id) != OPENED {
                marks.open(id);
            }
        }
    }
    let masks = join_masks(passes.into_iter().flat_map(|d| d.particles).collect());
    let hidden = Hidden::of(file, settings);
    emit(
        file,
        proj,
        marks,
        Some(&masks),
        hidden.as_ref(),
        achieved,
        DrawList::default(),
    )
}

/// Side of the square tiles the parallel occlusion traversal splits the image into.
const TILE_PX: u32 = 128;

/// The points the tiles of one parallel pass have committed, summed (a point drawn by
/// several tiles counts for each): when the sum passes `limit`, the pass is given up.
struct SharedCount {
    sum: std::sync::atomic::AtomicU64,
    limit: u64,
}

impl SharedCount {
    /// Adds `k`; false once the sum is past the limit.
    fn add(&self, k: u64) -> bool {
        let before = self.sum.fetch_add(k, std::sync::atomic::Ordering::Relaxed);
        before.saturating_add(k) <= self.limit
    }
}

/// How many commitments a tile makes between updates of the shared count.
const SHARED_BATCH: u64 = 1024;

/// A parallel pass is given up when the tiles' summed commitments pass the budget by
/// this factor: the tiles overlap by about a tenth (nodes on tile borders are visited by
/// each), so a pass that far past the budget cannot fit it; below that, the pass is
/// completed and the union of the tiles' cuts is checked against the budget exactly.
const SHARED_SLACK: f64 = 1.5;

/// [`traverse`] with occlusion culling, one front-to-back pass per tile of the image on
/// every core. Each tile has its own occlusion buffer over its pixels and visits only
/// the nodes whose boxes reach them; whether a node is opened or drawn depends on its
/// projected size alone, so the tiles agree on it, and the cut is the union of what the
/// tiles opened and drew (a node is left out when no tile can see it). The tiles do not
/// depend on the thread count, so neither does the cut. When the union exceeds the
/// budget, every tile starts over with the error 1.5× coarser.
fn traverse_tiled(
    camera: &Camera,
    file: &MdlodFile,
    settings: &TraversalSettings,
    residency: &dyn SharedResidency,
) -> (DrawList, Vec<(u32, f32)>) {
    use rayon::prelude::*;
    let proj = Projector::with_support(
        camera,
        settings.viewport,
        settings.support_scale,
        file.max_particle_radius(),
    );
    if !proj.visible(&file.nodes()[0]) || all_left_out(file, settings) {
        let list = DrawList {
            culled_nodes: 1,
            ..Default::default()
        };
        return (list, Vec::new());
    }
    let [w, h] = settings.viewport;
    let tiles: Vec<[u32; 2]> = (0..h.div_ceil(TILE_PX))
        .flat_map(|ty| (0..w.div_ceil(TILE_PX)).map(move |tx| [tx * TILE_PX, ty * TILE_PX]))
        .collect();
    let budget = settings.budget_points.max(1);
    let mut error_px = settings.error_px;
    for attempt in 0..MAX_RESTARTS {
        let shared = SharedCount {
            sum: 0.into(),
            limit: (budget as f64 * SHARED_SLACK).min(u64::MAX as f64) as u64,
        };
        let passes: Option<Vec<(Decisions, Asked)>> = tiles
            .par_iter()
            .map(|&origin| {
                let mut buffer = OcclusionBuffer::window(
                    camera,
                    settings.viewport,
                    settings.occlusion,
                    origin,
                    [TILE_PX, TILE_PX],
                )?;
                let mut tile = TileResidency {
                    shared: residency,
                    asked: Vec::new(),
                };
                let d = front_to_back(
                    camera,
                    file,
                    settings,
                    error_px,
                    &mut tile,
                    &mut buffer,
                    Some(&shared),
                )?;
                Some((d, tile.asked))
            })
            .collect();
        if let Some(passes) = passes {
            let (passes, asked): (Vec<Decisions>, Vec<Vec<(u32, f32)>>) =
                passes.into_iter().unzip();
            let asked = largest_first_once(asked.concat());
            let mut list = cut_of(file, &proj, settings, passes);
            if list.points <= budget {
                list.restarts = attempt;
                list.budget_limited = attempt > 0;
                list.deferred_nodes = asked
                    .iter()
                    .filter(|&&(id, _)| !residency.resident(file, id))
                    .count() as u64;
                return (list, asked);
            }
        }
        if error_px > proj.size_px(&file.nodes()[0]) {
            break;
        }
        error_px = coarser(error_px);
    }
    let mut tile = TileResidency {
        shared: residency,
        asked: Vec::new(),
    };
    let list = largest_first(camera, file, settings, &mut tile);
    (list, largest_first_once(tile.asked))
}

/// Coarsening steps (×1.5 each) the occlusion traversal tries before it falls back to
/// the largest-first cut, which always meets the budget.
const MAX_RESTARTS: u32 = 24;

/// The error of the occlusion traversal's next attempt after one over the budget.
fn coarser(error_px: f32) -> f32 {
    (error_px * 1.5).max(0.5)
}

/// The error the occlusion traversal drew a cut at after `restarts` restarts
/// ([`DrawList::restarts`]), when asked for `error_px`: coarser once per restart. Traversing at it from the start makes the same cut in one attempt.
/// (After its last restart the traversal falls back to the largest-first cut, which
/// records no restart: this is then the asked error, and the cut comes out the same way.)
pub fn error_of_restarts(error_px: f32, restarts: u32) -> f32 {
    (0..restarts).fold(error_px, |e, _| coarser(e))
}

/// The cut without occlusion: largest projected size first, up to the budget.
fn largest_first(
    camera: &Camera,
    file: &MdlodFile,
    settings: &TraversalSettings,
    residency: &mut dyn Residency,
) -> DrawList {
    let nodes = file.nodes();
    let levels = file.levels();
    let last = file.level_count() - 1;
    let proj = Projector::with_support(
        camera,
        settings.viewport,
        settings.support_scale,
        file.max_particle_radius(),
    );
    let budget = settings.budget_points.max(1);
    let mut list = DrawList::default();
    if !proj.visible(&nodes[0]) {
        list.culled_nodes = 1;
        return list;
    }
    // With hidden species: clusters of them only are culled, and mixed ones opened also
    // when small enough (after every larger node: see [`Frontier`]); hidden particles
    // are left out. Every species hidden draws nothing.
    if all_left_out(file, settings) {
        list.culled_nodes = 1;
        return list;
    }
    let hidden = Hidden::of(file, settings);
    let hidden_only = |id: usize| hidden.as_ref().is_some_and(|h| h.node(id));
    let hidden_particle = |i: usize, enc: usize| {
        hidden
            .as_ref()
            .is_some_and(|h| h.particle(i, enc).is_some())
    };
    let mixed = |id: usize| hidden.as_ref().is_some_and(|h| h.mixed(id));

    // With a residency whose answers do not depend on the order it is asked in, and a
    // budget no cut can reach (a cut draws at most one point per particle), which nodes
    // are opened does not depend on the order they are visited in either: they are then
    // walked depth first, without the heap that orders them by size (most of the time
    // of a cut of every particle).
    let particles = levels.get(last).map_or(0, |l| l.point_count);
    let mut frontier = if residency.order_free() && budget >= particles {
        Frontier::AnyOrder(Vec::new())
    } else {
        Frontier::LargestFirst(BinaryHeap::new(), BinaryHeap::new())
    };
    let mut marks = Marks::new(nodes.len());
    let error_px = settings.error_px;
    frontier.push(proj.size_px(&nodes[0]), 0, mixed(0), error_px);
    let mut drawn: u64 = 1;
    let mut achieved = 0.0f32;
    while let Some((size, id)) = frontier.pop(error_px) {
        if size <= error_px && !mixed(id as usize) {
            // Drawn as its representative; largest first, so is everything left.
            achieved = achieved.max(size);
            match frontier {
                Frontier::LargestFirst(..) => break,
                Frontier::AnyOrder(_) => continue,
            }
        }
        let n = &nodes[id as usize];
        let child_level = usize::from(n.level) + 1;
        if file.check_children(id as usize).is_err() {
            // Corrupt records below: drawn as its representative, the error kept for the
            // caller (`MdlodFile::node_error`).
            achieved = achieved.max(size);
            continue;
        }
        let children = n.child_first as usize..(n.child_first + n.child_count) as usize;
        let visible_children = if child_level == last {
            let enc = children_encoder(file, id as usize);
            children
                .clone()
                .filter(|&c| !hidden_particle(c, enc))
                .count() as u64
        } else {
            let first = levels[child_level].node_first as usize;
            children
                .clone()
                .filter(|&c| proj.visible(&nodes[first + c]) && !hidden_only(first + c))
                .count() as u64
        };
        if drawn - 1 + visible_children > budget {
            achieved = achieved.max(size);
            list.budget_limited = true;
            break;
        }
        if !residency.can_open(file, id, size) {
            achieved = achieved.max(size);
            list.deferred_nodes += 1;
            continue;
        }
        drawn = drawn - 1 + visible_children;
        marks.open(id);
        if child_level < last {
            let first = levels[child_level].node_first as usize;
            for c in children {
                let cn = &nodes[first + c];
                if proj.visible(cn) && !hidden_only(first + c) {
                    frontier.push(
                        proj.size_px(cn),
                        (first + c) as u32,
                        mixed(first + c),
                        error_px,
                    );
                }
            }
        }
    }
    emit(file, &proj, marks, None, hidden.as_ref(), achieved, list)
}

/// The nodes [`largest_first`] has yet to visit: by projected size, largest first (ties
/// by id), or in any order (last in, first out) where the order changes nothing. With
/// hidden species, clusters holding them and others are opened also when small enough:
/// those go into a second queue (largest first), visited once every node larger than the
/// error has been, so that a budget refines what is large on screen first.
enum Frontier {
    LargestFirst(
        BinaryHeap<(Size, Reverse<u32>)>,
        BinaryHeap<(Size, Reverse<u32>)>,
    ),
    AnyOrder(Vec<(f32, u32)>),
}

impl Frontier {
    /// Queues node `id` of projected size `size`; `mixed`: it must be opened whatever
    /// its size.
    fn push(&mut self, size: f32, id: u32, mixed: bool, error_px: f32) {
        match self {
            Frontier::LargestFirst(large, small) => {
                if mixed && size <= error_px {
                    small.push((Size(size), Reverse(id)));
                } else {
                    large.push((Size(size), Reverse(id)));
                }
            }
            Frontier::AnyOrder(v) => v.push((size, id)),
        }
    }

    fn pop(&mut self, error_px: f32) -> Option<(f32, u32)> {
        let take = |h: &mut BinaryHeap<(Size, Reverse<u32>)>| {
            h.pop().map(|(Size(s), Reverse(id))| (s, id))
        };
        match self {
            Frontier::LargestFirst(large, small) => {
                if large.peek().is_some_and(|(Size(s), _)| *s > error_px) || small.is_empty() {
                    take(large)
                } else {
                    take(small)
                }
            }
            Frontier::AnyOrder(v) => v.pop(),
        }
    }
}

/// What a cut with hidden species or clip planes leaves out: clusters of hidden species
/// only ([`MdlodFile::species_below`]) or wholly beyond a plane, and the particles of
/// hidden species or beyond a plane.
struct Hidden<'a> {
    /// What lies below each node ([`MdlodFile::hidden_below`]) and the particles' test.
    species: Option<(std::sync::Arc<[u8]>, HiddenTest)>,
    clip: ClipPlanes,
    /// How far decoded centres stray from their nodes' boxes ([`quantization_reach`]).
    grow: f32,
    file: &'a MdlodFile,
}

impl<'a> Hidden<'a> {
    /// What `settings` leave out of `file`: `None` when nothing.
    fn of(file: &'a MdlodFile, settings: &TraversalSettings) -> Option<Hidden<'a>> {
        let below = (!settings.hidden.is_empty()).then(|| file.hidden_below(&settings.hidden));
        (below.is_some() || !settings.clip.is_empty()).then(|| Hidden {
            species: below.map(|kinds| (kinds, file.hidden_test(&settings.hidden))),
            clip: settings.clip.for_file(file),
            grow: quantization_reach(file),
            file,
        })
    }
}

/// Whether `settings` leave out everything of `file`: every species hidden, or the top
/// node (all the particles) hidden or beyond a clip plane.
fn all_left_out(file: &MdlodFile, settings: &TraversalSettings) -> bool {
    let species_count = file.metadata().species.len();
    (species_count <= 64 && settings.hidden.species.count_ones() as usize == species_count)
        || Hidden::of(file, settings).is_some_and(|h| h.node(0))
}

/// The largest distance of a decoded centre from its input position (the file's recorded
/// quantization error; infinite where that is not a number).
fn quantization_reach(file: &MdlodFile) -> f32 {
    let e = file.metadata().max_position_error as f32;
    if e.is_finite() {
        e.max(0.0)
    } else {
        f32::INFINITY
    }
}

/// Why a particle is left out.
#[derive(Clone, Copy, PartialEq, Eq)]
enum LeftOut {
    Species,
    Clipped,
}

impl Hidden<'_> {
    fn clip_side(&self, id: usize) -> ClipSide {
        if self.clip.is_empty() {
            return ClipSide::Kept;
        }
        let Some(n) = self.file.nodes().get(id) else {
            return ClipSide::Across;
        };
        // Decoded centres stray from the box by at most the quantization error.
        self.clip.side(
            Vec3::from(n.bounds_min),
            Vec3::from(n.bounds_max),
            self.grow,
        )
    }

    /// Node `id` holds hidden particles only, or lies wholly beyond a clip plane.
    fn node(&self, id: usize) -> bool {
        self.species
            .as_ref()
            .is_some_and(|(kinds, _)| kinds.get(id) == Some(&BELOW_IN))
            || self.clip_side(id) == ClipSide::Beyond
    }

    /// Node `id` holds hidden particles and others, or lies across a clip plane.
    fn mixed(&self, id: usize) -> bool {
        let kind = self
            .species
            .as_ref()
            .and_then(|(kinds, _)| kinds.get(id).copied());
        match self.clip_side(id) {
            ClipSide::Beyond => false,
            ClipSide::Across => kind != Some(BELOW_IN),
            ClipSide::Kept => kind == Some(BELOW_IN | BELOW_OUT),
        }
    }

    /// Why particle `i`, decoded with encoding node `enc` ([`children_encoder`] of its
    /// parent), is left out, if it is.
    fn particle(&self, i: usize, enc: usize) -> Option<LeftOut> {
        if self
            .species
            .as_ref()
            .is_some_and(|(_, test)| self.file.hides_particle(test, i))
        {
            return Some(LeftOut::Species);
        }
        if self.clip.is_empty() {
            return None;
        }
        // The centre as the GPU decodes it.
        let file = self.file;
        let last = file.level_count() - 1;
        let enc = &file.nodes()[enc];
        let p = quantize::decode3(
            file.positions(last).get(i),
            enc.centroid,
            enc.quant_scale,
            file.position_bits(),
        );
        (!self.clip.keeps(Vec3::from(p))).then_some(LeftOut::Clipped)
    }
}

/// What one occlusion pass decided, over the whole image or one tile of it.
#[derive(Default)]
struct Decisions {
    /// Nodes opened (replaced by their children), in the order they were opened.
    opened: Vec<u32>,
    /// Nodes drawn as their representatives.
    committed: Vec<u32>,
    /// Largest projected size of a committed node.
    achieved: f32,
    /// Nodes refused by the residency.
    deferred: u64,
    /// For opened nodes whose children are particles (at most 64 of them): which
    /// children are drawn (bit `k`: child `k`); the others are hidden.
    particles: Vec<(u32, u64)>,
}

/// Sorts `(node, drawn children)` masks by node and joins a node's masks (a child is
/// drawn when any tile draws it).
fn join_masks(mut masks: Vec<(u32, u64)>) -> Vec<(u32, u64)> {
    masks.sort_unstable_by_key(|&(id, _)| id);
    masks.dedup_by(|later, kept| {
        let same = later.0 == kept.0;
        if same {
            kept.1 |= later.1;
        }
        same
    });
    masks
}

/// A key ordering nodes by depth as [`f32::total_cmp`] does, then by id: the depth's
/// bits made monotone as an unsigned integer, above the id.
fn depth_key(depth: f32, id: u32) -> u64 {
    let b = depth.to_bits();
    let ordered = if b >> 31 == 1 { !b } else { b | 0x8000_0000 };
    (u64::from(ordered) << 32) | u64::from(id)
}

/// A node in the occlusion traversal's queue: its [`depth_key`] (with the flag of a box
/// wholly inside the frustum) and its projected size and representative radius, worked
/// out when it was queued. Ordered so that the smallest key is popped first (keys are
/// unique: the id is part of them).
#[derive(Clone, Copy, Debug)]
struct Queued {
    key: u64,
    size: f32,
    own: f32,
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}

impl Eq for Queued {}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        other.key.cmp(&self.key)
    }
}

/// The cut with occlusion culling: nodes are visited nearest first; a node hidden by the
/// spheres committed so far is dropped with its subtree, one small enough (or not
/// resident) is committed as its representative, and the others are opened, committing
/// their particle children at once. `None` when the committed points exceed the budget
/// (the caller starts over with a coarser error). The top node must be in the frustum.
fn front_to_back(
    camera: &Camera,
    file: &MdlodFile,
    settings: &TraversalSettings,
    error_px: f32,
    residency: &mut dyn Residency,
    buffer: &mut OcclusionBuffer,
    shared: Option<&SharedCount>,
) -> Option<Decisions> {
    let nodes = file.nodes();
    let levels = file.levels();
    let last = file.level_count() - 1;
    let proj = Projector::with_support(
        camera,
        settings.viewport,
        settings.support_scale,
        file.max_particle_radius(),
    );
    let budget = settings.budget_points.max(1);
    let bits = file.position_bits();
    let radii: Vec<f32> = file.metadata().species.iter().map(|s| s.radius).collect();
    let species = file.species();
    // How far a drawn sphere of a subtree can reach past the node's box: representatives
    // are centred on a convex combination of their particles' centres, each at least the
    // smallest particle radius inside the box, with a radius no larger than the node's
    // (Eq. 2 makes radii grow up the hierarchy); every decoded centre moves by at most
    // the recorded quantization error.
    let r_min = file.min_particle_radius().max(0.0);
    // Particles' own radii, where the file keeps them.
    let own_radii = file.radii().zip(file.metadata().radius);
    let r_min = if r_min.is_finite() { r_min } else { 0.0 };
    let quant = quantization_reach(file);
    let mut out = Decisions::default();
    // Hidden species and values, clip planes: clusters left out wholly are culled, mixed
    // ones opened whatever their size, particles left out neither drawn nor occluding.
    let hidden = Hidden::of(file, settings);
    let hidden_only = |id: usize| hidden.as_ref().is_some_and(|h| h.node(id));
    let mixed = |id: usize| hidden.as_ref().is_some_and(|h| h.mixed(id));

    // The sphere a node is drawn as when it is not opened, exactly as the GPU decodes it.
    let representative = |id: u32| -> (Vec3, f32) {
        let n = &nodes[id as usize];
        if n.level == 0 {
            return (Vec3::from(n.centroid), representative_radius(n));
        }
        let level = usize::from(n.level);
        let enc = &nodes[children_encoder(file, n.parent as usize)];
        let q = file
            .positions(level)
            .get(id as usize - levels[level].node_first as usize);
        let p = quantize::decode3(q, enc.centroid, enc.quant_scale, bits);
        (Vec3::from(p), representative_radius(n))
    };

    // Nearest first (ties by id), each with whether its box lies wholly inside the
    // frustum (then its descendants' boxes do too and are not tested). The flag rides in
    // the key's bit above the id when ids leave it free (files of fewer than 2^31 nodes;
    // larger ones test every node against the frustum).
    let inside_bit: u64 = if nodes.len() <= 1 << 31 { 1 << 31 } else { 0 };
    let entry = |depth: f32, id: u32, inside: bool, size: f32, own: f32| Queued {
        key: depth_key(depth, id) | if inside { inside_bit } else { 0 },
        size,
        own,
    };
    let mut heap: BinaryHeap<Queued> = BinaryHeap::new();
    let (top_size, top_near) = proj.size_and_near(&nodes[0]);
    heap.push(entry(
        top_near,
        0,
        proj.frustum(&nodes[0]) == Some(true),
        top_size,
        representative_radius(&nodes[0]),
    ));
    // The visible children of the node being considered: (index on their level,
    // projected size, representative radius, wholly inside the frustum, near depth),
    // computed once for the node's own test and for committing or queueing them.
    let mut kids: Vec<(u32, f32, f32, bool, f32)> = Vec::new();
    let mut committed: u64 = 0;
    let mut reported: u64 = 0;
    let mut achieved = 0.0f32;
    while let Some(Queued { key, size, own }) = heap.pop() {
        let inside = key & inside_bit != 0;
        let id = (key & !inside_bit) as u32;
        if let Some(shared) = shared {
            if committed - reported >= SHARED_BATCH {
                if !shared.add(committed - reported) {
                    return None;
                }
                reported = committed;
            }
        }
        let n = &nodes[id as usize];
        let (bounds_min, bounds_max) = (Vec3::from(n.bounds_min), Vec3::from(n.bounds_max));
        // First with the node's own representative radius, which bounds every sphere
        // drawn for its subtree (radii only grow up the hierarchy): hidden with that
        // margin is hidden with the tighter one below, whose children need not be read.
        let margin_of = |reach: f32| (reach - r_min).max(0.0) + quant;
        let child_level = usize::from(n.level) + 1;
        let opens = size > error_px || mixed(id as usize);
        let reads_children = opens && child_level < last;
        if reads_children && buffer.box_hidden(bounds_min, bounds_max, margin_of(own)) {
            continue;
        }
        let children = n.child_first..n.child_first + n.child_count;
        kids.clear();
        // The largest representative that can be drawn for this subtree: its own when
        // it is small enough to be drawn, else its visible children's (none below a
        // node whose children are particles). A node that is then refused by the
        // residency is drawn as its representative: a streaming frame, never the
        // converged image, may miss where that larger sphere pokes out of a hidden box.
        // Corrupt records below: drawn as its representative, as a node the residency
        // refuses, the error kept for the caller (`MdlodFile::node_error`).
        let corrupt = reads_children && file.check_children(id as usize).is_err();
        let reach = if !opens || corrupt {
            own
        } else if child_level == last {
            0.0
        } else {
            let first = levels[child_level].node_first as usize;
            let mut reach = 0.0f32;
            for c in children.clone() {
                let cn = &nodes[first + c as usize];
                let within = if inside { Some(true) } else { proj.frustum(cn) };
                if let Some(within) = within.filter(|_| !hidden_only(first + c as usize)) {
                    let r = representative_radius(cn);
                    reach = reach.max(r);
                    let (size, near) = proj.size_and_near(cn);
                    kids.push((c, size, r, within, near));
                }
            }
            reach
        };
        if (!reads_children || reach < own)
            && buffer.box_hidden(bounds_min, bounds_max, margin_of(reach))
        {
            continue;
        }
        let commit = !opens || corrupt || {
            let refused = !residency.can_open(file, id, size);
            out.deferred += u64::from(refused);
            refused
        };
        if commit {
            achieved = achieved.max(size);
            committed += 1;
            if committed > budget {
                return None;
            }
            out.committed.push(id);
            let (c, r) = representative(id);
            buffer.add_sphere(c, r);
            continue;
        }
        out.opened.push(id);
        let enc_id = children_encoder(file, id as usize);
        let enc = &nodes[enc_id];
        let positions = file.positions(child_level);
        if child_level < last {
            // Children too large are queued by depth; the others are final, so each is
            // tested and committed at once rather than after a round through the queue
            // (what is nearer than their parent is committed already; the queue would
            // only add what lies between the two depths).
            let first = levels[child_level].node_first as usize;
            for &(c, csize, r, within, near) in &kids {
                let cid = first + c as usize;
                if csize > error_px || mixed(cid) {
                    heap.push(entry(near, cid as u32, within, csize, r));
                    continue;
                }
                // The one sphere drawn for it, as the GPU decodes it (grown by the
                // quantization error, against rounding), is a much tighter test than
                // the node's box grown by the radius.
                let p = Vec3::from(quantize::decode3(
                    positions.get(c as usize),
                    enc.centroid,
                    enc.quant_scale,
                    bits,
                ));
                if buffer.sphere_hidden(p, r + quant) {
                    continue;
                }
                achieved = achieved.max(csize);
                committed += 1;
                if committed > budget {
                    return None;
                }
                out.committed.push(cid as u32);
                buffer.add_sphere(p, r);
            }
        } else {
            // Particles: each is tested by the box of its own sphere (as for small
            // children above) when the node has at most 64, so that a mask can say
            // which are drawn; more than that are all drawn.
            let masked = n.child_count <= 64;
            let mut mask = 0u64;
            let mut drawn = 0u64;
            for (k, c) in children.enumerate() {
                if hidden
                    .as_ref()
                    .is_some_and(|h| h.particle(c as usize, enc_id).is_some())
                {
                    continue;
                }
                let p = Vec3::from(quantize::decode3(
                    positions.get(c as usize),
                    enc.centroid,
                    enc.quant_scale,
                    bits,
                ));
                let s = species
                    .get(c as usize)
                    .map_or(0, |&s| usize::from(s).min(radii.len().saturating_sub(1)));
                let r = match own_radii {
                    Some((q, _)) => q.get(c as usize).map_or(0.0, |&q| file.radius_of(q)),
                    None => radii.get(s).copied().unwrap_or(0.0),
                };
                if masked {
                    if buffer.sphere_hidden(p, r + quant) {
                        continue;
                    }
                    mask |= 1 << k;
                }
                drawn += 1;
                buffer.add_sphere(p, r);
            }
            if masked {
                out.particles.push((id, mask));
            }
            committed += drawn;
            if committed > budget {
                return None;
            }
        }
    }
    out.achieved = achieved;
    Some(out)
}

/// Turns the opened nodes into draw ranges. With `recorded` (the occlusion traversal's
/// particle masks, sorted by node), an opened node draws its node children marked drawn
/// (a child neither drawn nor opened inside the frustum was hidden) and its particle
/// children that its mask draws (all of them without a mask). Without, it draws its
/// node children neither opened nor outside the frustum and every particle child.
fn emit(
    file: &MdlodFile,
    proj: &Projector,
    mut marks: Marks,
    recorded: Option<&[(u32, u64)]>,
    hidden: Option<&Hidden<'_>>,
    achieved: f32,
    mut list: DrawList,
) -> DrawList {
    if marks.get(0) != OPENED {
        if recorded.is_some() && marks.get(0) != DRAWN {
            list.occluded_nodes = 1;
            return list;
        }
        list.ranges.push(DrawRange {
            level: 0,
            first: 0,
            count: 1,
            quant_node: 0,
        });
        list.representatives = 1;
        count_mixed(hidden, 0, &mut list);
        list.points = 1;
        list.error_px = achieved;
        return list;
    }
    use rayon::prelude::*;
    let mut open = std::mem::take(&mut marks.open);
    open.par_sort_unstable();
    // Each chunk of opened nodes on its own core; the parts are joined in order.
    let parts: Vec<DrawList> = open
        .par_chunks(EMIT_CHUNK)
        .map(|chunk| {
            let mut part = DrawList::default();
            for &id in chunk {
                emit_node(file, proj, &marks, recorded, hidden, id, &mut part);
            }
            part
        })
        .collect();
    for part in parts {
        list.ranges.extend(part.ranges);
        list.particles += part.particles;
        list.representatives += part.representatives;
        list.culled_nodes += part.culled_nodes;
        list.occluded_nodes += part.occluded_nodes;
        list.occluded_particles += part.occluded_particles;
        list.hidden_particles += part.hidden_particles;
        list.clipped_particles += part.clipped_particles;
        list.mixed_drawn += part.mixed_drawn;
        list.across_drawn += part.across_drawn;
    }
    list.opened_nodes = open.len() as u64;
    list.points = list.particles + list.representatives;
    list.error_px = achieved;
    list
}

/// Counts node `id`, drawn as its representative, when it still holds hidden species
/// or lies across a clip plane.
fn count_mixed(hidden: Option<&Hidden<'_>>, id: usize, list: &mut DrawList) {
    if let Some(h) = hidden {
        list.mixed_drawn += u64::from(
            h.species
                .as_ref()
                .is_some_and(|(kinds, _)| kinds.get(id) == Some(&(BELOW_IN | BELOW_OUT))),
        );
        list.across_drawn += u64::from(h.clip_side(id) == ClipSide::Across);
    }
}

/// Opened nodes per chunk of the parallel emission.
const EMIT_CHUNK: usize = 4096;

/// The ranges of opened node `id`'s drawn children, added to `list` (see [`emit`]).
fn emit_node(
    file: &MdlodFile,
    proj: &Projector,
    marks: &Marks,
    recorded: Option<&[(u32, u64)]>,
    hidden: Option<&Hidden<'_>>,
    id: u32,
    list: &mut DrawList,
) {
    let nodes = file.nodes();
    let levels = file.levels();
    let last = file.level_count() - 1;
    let n = &nodes[id as usize];
    let child_level = usize::from(n.level) + 1;
    let enc = children_encoder(file, id as usize) as u32;
    let children = n.child_first..n.child_first + n.child_count;
    let mut run: Option<(u32, u32)> = None;
    let flush = |run: &mut Option<(u32, u32)>, list: &mut DrawList| {
        if let Some((first, count)) = run.take() {
            list.ranges.push(DrawRange {
                level: child_level as u8,
                first,
                count,
                quant_node: enc,
            });
            if child_level == last {
                list.particles += u64::from(count);
            } else {
                list.representatives += u64::from(count);
            }
        }
    };
    let mask = if child_level == last {
        recorded.and_then(|m| {
            m.binary_search_by_key(&id, |&(node, _)| node)
                .ok()
                .map(|i| m[i].1)
        })
    } else {
        None
    };
    for (k, c) in children.enumerate() {
        let draw = if child_level == last {
            let left_out = hidden.and_then(|h| h.particle(c as usize, enc as usize));
            if let Some(why) = left_out {
                match why {
                    LeftOut::Species => list.hidden_particles += 1,
                    LeftOut::Clipped => list.clipped_particles += 1,
                }
                false
            } else {
                let drawn = mask.is_none_or(|m| m >> k & 1 == 1);
                list.occluded_particles += u64::from(!drawn);
                drawn
            }
        } else {
            let cid = levels[child_level].node_first as u32 + c;
            match marks.get(cid) {
                OPENED => false,
                DRAWN => {
                    count_mixed(hidden, cid as usize, list);
                    true
                }
                _ => {
                    let hidden_only = hidden.is_some_and(|h| h.node(cid as usize));
                    if !proj.visible(&nodes[cid as usize]) || hidden_only {
                        list.culled_nodes += 1;
                        false
                    } else if recorded.is_some() {
                        list.occluded_nodes += 1;
                        false
                    } else {
                        count_mixed(hidden, cid as usize, list);
                        true
                    }
                }
            }
        };
        match (&mut run, draw) {
            (Some((_, count)), true) => *count += 1,
            (None, true) => run = Some((c, 1)),
            (_, false) => flush(&mut run, list),
        }
    }
    flush(&mut run, list);
}

/// Which species (by index) the cut `draw` shows: those of its particles and of the
/// particles below its clusters (each cluster's descendants are one range of the finest
/// level). Reads at most every particle's species once, stopping when all are seen;
/// records of a corrupt file are read with checks, and what they do not reach is left out.
pub fn species_drawn(file: &MdlodFile, draw: &DrawList) -> Vec<bool> {
    let count = file.metadata().species.len();
    let mut seen = vec![false; count];
    let mut left = count;
    let species = file.species();
    let last = file.level_count().saturating_sub(1);
    for r in &draw.ranges {
        let (mut a, mut b) = (
            r.first as usize,
            (r.first as usize).saturating_add(r.count as usize),
        );
        let mut level = usize::from(r.level);
        while level < last && a < b {
            let nodes = file.level_nodes(level);
            let (Some(na), Some(nb)) = (nodes.get(a), nodes.get(b - 1)) else {
                a = b;
                break;
            };
            a = na.child_first as usize;
            b = (nb.child_first as usize).saturating_add(nb.child_count as usize);
            level += 1;
        }
        for &s in species.get(a..b).unwrap_or(&[]) {
            if let Some(x) = seen.get_mut(usize::from(s)) {
                if !*x {
                    *x = true;
                    left -= 1;
                }
            }
        }
        if left == 0 {
            break;
        }
    }
    seen
}

/// World positions of every point of `draw`, in draw order, decoded as the GPU does.
pub fn point_positions(file: &MdlodFile, draw: &DrawList) -> Vec<Vec3> {
    let nodes = file.nodes();
    let bits = file.position_bits();
    let mut out = Vec::with_capacity(draw.points as usize);
    for r in &draw.ranges {
        let level = usize::from(r.level);
        if level == 0 {
            out.push(Vec3::from(nodes[0].centroid));
            continue;
        }
        let enc = &nodes[r.quant_node as usize];
        let pos = file.positions(level);
        for i in r.first..r.first + r.count {
            let q = pos.get(i as usize);
            out.push(Vec3::from(quantize::decode3(
                q,
                enc.centroid,
                enc.quant_scale,
                bits,
            )));
        }
    }
    out
}

/// How blending that needs depth order sorts a cut, back to front.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthOrder {
    /// The hierarchy's order (Hopf & Ertl 2003, section 6): the cut's clusters (each
    /// range: the children of one node) bucket-sorted by the depth of their centroid,
    /// linear in the clusters, then each cluster's points sorted. Exact within a
    /// cluster; where clusters overlap in depth, their points do not interleave.
    #[default]
    Clusters,
    /// Every point sorted by its own depth: exact, `O(n log n)` in the points.
    Points,
}

impl DepthOrder {
    pub fn name(self) -> &'static str {
        match self {
            DepthOrder::Clusters => "clusters",
            DepthOrder::Points => "points",
        }
    }
}

/// `draw` as one range per point in `order`, back to front (farthest view depth first;
/// ties by level and index).
pub fn sort_back_to_front_by(
    file: &MdlodFile,
    draw: &DrawList,
    camera: &Camera,
    order: DepthOrder,
) -> DrawList {
    if order == DepthOrder::Points {
        return sort_back_to_front(file, draw, camera);
    }
    let view = camera.view_from_world();
    let depth: Vec<f32> = point_positions(file, draw)
        .iter()
        .map(|w| -view.transform_point3(*w).z)
        .collect();
    // Each cluster's centroid depth (depth is affine in position: the mean of its
    // points' depths), and where its points start.
    let mut clusters = Vec::with_capacity(draw.ranges.len());
    let mut at = 0usize;
    for r in &draw.ranges {
        let n = (r.count as usize).min(depth.len() - at.min(depth.len()));
        let d = &depth[at..at + n];
        let mean = d.iter().map(|&v| f64::from(v)).sum::<f64>() / n.max(1) as f64;
        clusters.push((mean as f32, at, n));
        at += n;
    }
    // Bucket sort, farthest first: as many buckets as clusters (at least 1024), stable.
    let (lo, hi) = clusters
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c.0), hi.max(c.0))
        });
    let buckets = clusters.len().max(1024);
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let bucket = |d: f32| {
        let b = ((hi - d) / span * buckets as f32) as usize;
        if b >= buckets {
            buckets - 1
        } else {
            b
        }
    };
    let mut start = vec![0usize; buckets + 1];
    for c in &clusters {
        start[bucket(c.0) + 1] += 1;
    }
    for b in 0..buckets {
        start[b + 1] += start[b];
    }
    let mut sorted = vec![0usize; clusters.len()];
    for (k, c) in clusters.iter().enumerate() {
        let b = bucket(c.0);
        sorted[start[b]] = k;
        start[b] += 1;
    }
    let mut ranges = Vec::with_capacity(depth.len());
    let mut points: Vec<(f32, u32)> = Vec::new();
    for k in sorted {
        let (r, (_, at, n)) = (&draw.ranges[k], clusters[k]);
        points.clear();
        points.extend((0..n).map(|j| (depth[at + j], r.first + j as u32)));
        points.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        ranges.extend(points.iter().map(|&(_, i)| DrawRange {
            level: r.level,
            first: i,
            count: 1,
            quant_node: r.quant_node,
        }));
    }
    DrawList {
        ranges,
        ..draw.clone()
    }
}

/// `draw` as one range per point, ordered back to front (farthest view depth first; ties
/// by level and index), for blending that needs depth order: [`DepthOrder::Points`].
pub fn sort_back_to_front(file: &MdlodFile, draw: &DrawList, camera: &Camera) -> DrawList {
    let view = camera.view_from_world();
    let positions = point_positions(file, draw);
    let mut points: Vec<(f32, DrawRange)> = Vec::with_capacity(positions.len());
    let mut p = positions.iter();
    for r in &draw.ranges {
        for i in r.first..r.first + r.count {
            let depth = p.next().map_or(0.0, |w| -view.transform_point3(*w).z);
            points.push((
                depth,
                DrawRange {
                    level: r.level,
                    first: i,
                    count: 1,
                    quant_node: r.quant_node,
                },
            ));
        }
    }
    points.sort_by(|a, b| {
        b.0.total_cmp(&a.0)
            .then(a.1.level.cmp(&b.1.level))
            .then(a.1.first.cmp(&b.1.first))
    });
    DrawList {
        ranges: points.into_iter().map(|(_, r)| r).collect(),
        ..draw.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest first; clusters holding hidden and shown species that are small enough
    /// come after every node larger than the error (largest of them first), before the
    /// small ones that end the walk.
    #[test]
    fn small_mixed_clusters_are_visited_after_every_large_node() {
        let mut f = Frontier::LargestFirst(BinaryHeap::new(), BinaryHeap::new());
        for (size, id, mixed) in [
            (0.7, 1, false),
            (0.5, 2, true),
            (10.0, 3, false),
            (0.9, 4, true),
            (5.0, 5, true),
            (2.0, 6, false),
        ] {
            f.push(size, id, mixed, 1.0);
        }
        let order: Vec<u32> = std::iter::from_fn(|| f.pop(1.0))
            .map(|(_, id)| id)
            .collect();
        assert_eq!(order, [3, 5, 6, 4, 2, 1]);
    }

    /// Batches hold the list's points in order, within both limits, each range cut only
    /// where a batch fills up.
    #[test]
    fn batches_keep_every_point_in_order_within_the_limits() {
        let range = |level: u8, first: u32, count: u32| DrawRange {
            level,
            first,
            count,
            quant_node: u32::from(level) * 10,
        };
        let draw = DrawList {
            ranges: vec![
                range(0, 0, 1),
                range(2, 5, 7),
                range(3, 0, 3),
                range(3, 9, 12),
            ],
            points: 23,
            ..Default::default()
        };
        let flat = |lists: &[DrawList]| -> Vec<(u8, u32, u32)> {
            lists
                .iter()
                .flat_map(|l| &l.ranges)
                .flat_map(|r| (r.first..r.first + r.count).map(move |i| (r.level, i, r.quant_node)))
                .collect()
        };
        let want = flat(std::slice::from_ref(&draw));
        for (max_points, max_ranges) in [(1, 1), (2, 8), (5, 2), (7, 3), (23, 4), (100, 100)] {
            let batches = draw.batches(max_points, max_ranges);
            assert_eq!(flat(&batches), want, "{max_points} {max_ranges}");
            for b in &batches {
                assert!(b.points <= u64::from(max_points) && b.ranges.len() <= max_ranges);
                assert_eq!(
                    b.points,
                    b.ranges.iter().map(|r| u64::from(r.count)).sum::<u64>()
                );
                assert!(b.ranges.iter().all(|r| r.count > 0));
            }
            // Only the last batch may be short of both limits.
            for b in &batches[..batches.len() - 1] {
                assert!(b.points == u64::from(max_points) || b.ranges.len() == max_ranges);
            }
        }
        assert_eq!(draw.batches(4, 4).len(), 6);
        assert_eq!(draw.batches(100, 3).len(), 2);
        let empty = DrawList::default().batches(10, 10);
        assert_eq!(empty.len(), 1);
        assert!(empty[0].ranges.is_empty());
    }

    /// The heap key orders by depth exactly as `f32::total_cmp`, then by id.
    #[test]
    fn depth_keys_order_as_total_cmp_then_id() {
        let depths = [
            f32::NEG_INFINITY,
            -1e30,
            -2.5,
            -f32::MIN_POSITIVE,
            -0.0,
            0.0,
            f32::MIN_POSITIVE,
            1e-3,
            1.0,
            1.000_000_1,
            7e20,
            f32::INFINITY,
        ];
        for &a in &depths {
            for &b in &depths {
                for (ia, ib) in [(0u32, 1u32), (5, 5), (u32::MAX, 0)] {
                    let want = a.total_cmp(&b).then(ia.cmp(&ib));
                    assert_eq!(depth_key(a, ia).cmp(&depth_key(b, ib)), want, "{a} {b}");
                }
            }
        }
    }
}
