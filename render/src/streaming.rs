//! Out-of-core rendering: a fixed GPU memory pool of pages with least-recently-used
//! eviction, filled by a background loader thread in order of screen size.
//!
//! How it works.
//! - A *page* is a fixed number ([`PAGE_POINTS`] by default) of consecutive points of one level (the last page of a
//!   level may be shorter). Its GPU form is a *slot*: the raw quantized position words
//!   of its points, and at most two attribute words per point, packed as the pool's
//!   [`PackStyle`] and look ask ([`AttrPacker`], the packer of whole cuts too): species
//!   index or radius and colour for spheres, flux radius and colour or intensity for
//!   splats and densities. Every slot has the same size, so the pool is
//!   two fixed buffers (positions, attributes) of `capacity` slots plus one reserved
//!   slot holding the top node; there is no fragmentation.
//! - Each frame first installs the pages the loader has finished: into a free slot, or
//!   else into the least recently used slot not used by the previous frame (an
//!   eviction). Then it runs the traversal ([`crate::traversal::traverse_shared`], in
//!   tiles on every core), which lets a node open only when every page holding its
//!   children is resident. A node whose pages are missing stays drawn as its
//!   representative, so a missing subtree is drawn by its nearest resident ancestor,
//!   and its pages are requested with the node's projected size as priority. The nodes
//!   the cut asked to open are then answered once more in one order, those opened
//!   first and then the others largest first, through a [`Residency`] that marks their
//!   pages used this frame: a missing node whose pages would not fit in the pool
//!   together with the pages already used is not requested (the pool, like the point
//!   budget, caps the cut), so the working set of a still view always fits and loading
//!   converges.
//! - On the second frame of a still view, the view's complete cut (the traversal as if
//!   everything were resident) is computed once and its pages requested within the
//!   pool: a still view then completes in about three frames instead of one frame per
//!   level of its cut. From then on the complete cut's pages are marked before those the
//!   frame draws, and the frame traverses at the error the complete cut was drawn at (a
//!   budget can make it coarser than asked), so a pool that holds the complete cut
//!   always reaches it: the pages of the coarser cuts drawn on the way are evicted for
//!   it, never the other way round.
//! - Requests go to the loader thread largest first; it copies the pages out of the
//!   memory-mapped file (taking the page faults off the render thread) and sends them
//!   back, before each page taking in what later frames asked for, so the largest
//!   page wanted goes first across frames. Each drawn range is split at page boundaries
//!   and points into its slots; a cut larger than one storage binding is bound in
//!   batches, as the passes bind any cut.
//! - Once a frame requests nothing and has nothing in flight, it is *complete*: with a
//!   pool large enough for the cut it draws exactly what [`crate::render_image`] draws.
//! - [`StreamingRenderer::render`] draws spheres; [`StreamingRenderer::prepare`] does a
//!   frame's bookkeeping alone, and the pool then binds the cut as a [`CutSource`] for
//!   any pass (splats, the density volume: [`crate::render_stream_frame`]).

use std::collections::BinaryHeap;
use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mdlod_format::MdlodFile;

use crate::camera::Camera;
use crate::error::RenderError;
use crate::passes::sphere_raycast::{
    push_bytes_as_words, storage_buffer, AttrPacker, PackStyle, RangeGpu, SphereInputs,
};
use crate::renderer::{BoundCut, CutSource, FrameSettings, RenderedFrame, Renderer};
use crate::style::PointStyle;
use crate::traversal::{traverse_shared, DrawList, Residency, SharedResidency, TraversalSettings};

/// Default points per page. Small pages waste little of the pool on points no view
/// draws: at 2×10^8 particles, a 1 px view through a 512 MiB pool (128 MiB buffers on
/// lavapipe) completed at 0 px error in 3 frames with 64-point pages, and settled at
/// 2.5 px after 8 frames with 256-point pages, the pool full.
pub const PAGE_POINTS: u32 = 64;

/// A page: points `page * page_points ..` of `level` (≥ 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PageId {
    pub level: u8,
    pub page: u32,
}

/// Hashes a page id by multiplying and folding (a page id is five bytes): the default
/// SipHash took a quarter of a 2×10^8-particle frame's bookkeeping, which looks up
/// hundreds of thousands of pages.
#[derive(Clone, Copy, Default)]
struct PageHasher(u64);

impl Hasher for PageHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 32)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u8(&mut self, v: u8) {
        self.write_u64(u64::from(v));
    }

    fn write_u32(&mut self, v: u32) {
        self.write_u64(u64::from(v));
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

type PageMap<V> = HashMap<PageId, V, BuildHasherDefault<PageHasher>>;
type PageSet = HashSet<PageId, BuildHasherDefault<PageHasher>>;

/// What a streaming frame did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StreamStats {
    /// Frame number (1 for the first).
    pub frame: u64,
    /// Pages that fit in the pool.
    pub capacity_pages: usize,
    pub resident_pages: usize,
    /// Pages the cut of this frame used.
    pub used_pages: usize,
    /// Pages installed at the start of this frame.
    pub installed: usize,
    /// Pages evicted to make room this frame.
    pub evicted: usize,
    /// Pages evicted since the renderer was made.
    pub evicted_total: u64,
    /// Pages requested this frame.
    pub requested: usize,
    /// Requests in flight after this frame.
    pub pending: usize,
    /// True when the pool capacity kept a node from opening.
    pub pool_limited: bool,
    /// Nothing was missing and nothing is in flight: more frames of this view draw the
    /// same cut.
    pub complete: bool,
}

impl StreamStats {
    /// More frames of this view would draw the same image: it is complete, or the pool
    /// is full and nothing more arrives or is asked for (the best this pool can hold).
    pub fn settled(&self) -> bool {
        self.complete || (self.installed == 0 && self.requested == 0 && self.pending == 0)
    }
}

struct LoadedPage {
    id: PageId,
    positions: Vec<u32>,
    attrs: Vec<u32>,
    /// Why the page could not be packed (a corrupt species index, a bad node record).
    error: Option<RenderError>,
}

#[derive(Clone, Copy)]
struct Slot {
    page: PageId,
    last_used: u64,
}

/// Renders a file through a fixed-size GPU page pool (see the module docs).
pub struct StreamingRenderer<'r> {
    renderer: &'r Renderer,
    file: Arc<MdlodFile>,
    capacity: usize,
    page_points: u32,
    slot_pos_words: u32,
    slot_attr_words: u32,
    positions: wgpu::Buffer,
    attrs: wgpu::Buffer,
    species: wgpu::Buffer,
    packer: AttrPacker,
    look: PointStyle,
    slots: Vec<Option<Slot>>,
    resident: PageMap<u32>,
    pending: PageSet,
    /// Slots from here on have never held a page (an evicted slot is refilled at once,
    /// so these are the only empty ones).
    unused: u32,
    frame: u64,
    evicted_total: u64,
    /// Requests to the loader: pages with their priority (projected size in pixels).
    requests: Option<Sender<Vec<(f32, PageId)>>>,
    loaded: Receiver<LoadedPage>,
    /// Tells the loader to stop at its next page (set when the renderer is dropped).
    stop: Arc<AtomicBool>,
    /// Pages received by [`StreamingRenderer::wait_for_loads`], installed next frame.
    backlog: Vec<LoadedPage>,
    loader: Option<JoinHandle<()>>,
    /// The view of the last frame.
    last_view: Option<(Camera, TraversalSettings)>,
    /// The complete cut of that view, once it was still for two frames and looked ahead
    /// (see [`StreamingRenderer::prepare`]).
    complete_cut: Option<CompleteCut>,
    /// Pages installed this frame and not yet written to the pool's buffers.
    staged: SlotWrites,
}

/// A still view's complete cut: what the traversal decides with every page resident.
struct CompleteCut {
    /// Times the occlusion traversal restarted coarser to meet the budget (the error it
    /// was drawn at follows: [`crate::traversal::error_of_restarts`]).
    restarts: u32,
    /// The nodes it opens, with their projected sizes, largest first.
    nodes: Vec<(u32, f32)>,
}

/// A run of consecutive slots' words, written to the pool in one go.
#[derive(Default)]
struct SlotWrites {
    first: u32,
    slots: u32,
    positions: Vec<u32>,
    attrs: Vec<u32>,
}

/// The largest run of attribute words staged before it is written (bytes).
const STAGED_BYTES: usize = 16 << 20;

impl std::fmt::Debug for StreamingRenderer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamingRenderer")
            .field("capacity", &self.capacity)
            .field("resident", &self.resident.len())
            .field("frame", &self.frame)
            .finish_non_exhaustive()
    }
}

fn page_range(file: &MdlodFile, id: PageId, page_points: u32) -> std::ops::Range<usize> {
    let count = file.levels()[usize::from(id.level)].point_count as usize;
    let a = id.page as usize * page_points as usize;
    a..(a + page_points as usize).min(count)
}

fn load_page(file: &MdlodFile, id: PageId, page_points: u32, packer: &AttrPacker) -> LoadedPage {
    let level = usize::from(id.level);
    let r = page_range(file, id, page_points);
    let bpp = 3 * (file.position_bits() as usize / 8);
    let mut positions = Vec::new();
    push_bytes_as_words(
        &mut positions,
        &file.positions(level).bytes()[r.start * bpp..r.end * bpp],
    );
    let mut attrs = Vec::new();
    let error = packer.push(file, level, r.start, r.len(), &mut attrs).err();
    LoadedPage {
        id,
        positions,
        attrs,
        error,
    }
}

/// A request in the loader's queue: larger pages first, then earlier requests.
#[derive(PartialEq)]
struct Queued {
    size_px: f32,
    order: u64,
    id: PageId,
}

impl Eq for Queued {}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.size_px
            .total_cmp(&other.size_px)
            .then(other.order.cmp(&self.order))
    }
}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// The loader thread: takes every batch of requests that has come in into one queue
/// before each page, so a page a later frame asks for goes ahead of smaller pages of
/// earlier frames (largest first across frames, not batch after batch), loads the
/// largest with `load` and sends it back. Returns when `stop` is set (checked before
/// every page: a dropped renderer does not wait for the queue to drain), when the
/// requests end and the queue is empty, or when nobody receives.
fn run_loader(
    requests: &Receiver<Vec<(f32, PageId)>>,
    loaded: &Sender<LoadedPage>,
    stop: &AtomicBool,
    load: impl Fn(PageId) -> LoadedPage,
) {
    let mut queue = BinaryHeap::new();
    let mut order = 0u64;
    let mut take = |batch: Vec<(f32, PageId)>, queue: &mut BinaryHeap<Queued>| {
        for (size_px, id) in batch {
            queue.push(Queued { size_px, order, id });
            order += 1;
        }
    };
    loop {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        if queue.is_empty() {
            match requests.recv() {
                Ok(batch) => take(batch, &mut queue),
                Err(_) => return,
            }
        }
        while let Ok(batch) = requests.try_recv() {
            take(batch, &mut queue);
        }
        let Some(next) = queue.pop() else { continue };
        let page = load(next.id);
        if stop.load(Ordering::Relaxed) || loaded.send(page).is_err() {
            return;
        }
    }
}

impl<'r> StreamingRenderer<'r> {
    /// Frames drawn so far.
    pub fn frames_drawn(&self) -> u64 {
        self.frame
    }

    /// The file streamed.
    pub fn file(&self) -> &Arc<MdlodFile> {
        &self.file
    }

    /// A pool of at most `pool_bytes` of GPU memory (at least one page, at most what one
    /// storage binding holds) for `file`, with pages of [`PAGE_POINTS`] points.
    pub fn new(
        renderer: &'r Renderer,
        file: Arc<MdlodFile>,
        pool_bytes: u64,
    ) -> Result<Self, RenderError> {
        Self::with_page_points(renderer, file, pool_bytes, PAGE_POINTS)
    }

    /// Bytes of GPU memory one page takes for a file of `position_bits`.
    pub fn slot_bytes(position_bits: u32, page_points: u32) -> u64 {
        u64::from(page_points) * u64::from(3 * position_bits / 8 + 2 * 4)
    }

    /// [`Self::new`] with pages of `page_points` points (a multiple of 4, at least 4).
    pub fn with_page_points(
        renderer: &'r Renderer,
        file: Arc<MdlodFile>,
        pool_bytes: u64,
        page_points: u32,
    ) -> Result<Self, RenderError> {
        Self::with_style(
            renderer,
            file,
            pool_bytes,
            page_points,
            PackStyle::Spheres,
            &PointStyle::default(),
        )
    }

    /// A pool whose pages carry the points as `style` packs them, with the look `look`
    /// (spheres only): the pool then feeds the passes of that style (splats, the density
    /// volume, styled spheres). See [`crate::passes::sphere_raycast::AttrPacker`].
    pub fn with_style(
        renderer: &'r Renderer,
        file: Arc<MdlodFile>,
        pool_bytes: u64,
        page_points: u32,
        style: PackStyle,
        look: &PointStyle,
    ) -> Result<Self, RenderError> {
        let packer = AttrPacker::new(&file, style, look)?;
        if page_points < 4 || !page_points.is_multiple_of(4) || page_points > 1 << 20 {
            return Err(RenderError::InvalidOptions(format!(
                "{page_points} points per page (must be a multiple of 4 from 4 to 2^20)"
            )));
        }
        let bits = file.position_bits();
        let slot_pos_words = page_points * 3 * bits / 32;
        let slot_attr_words = page_points * 2;
        let slot_bytes = Self::slot_bytes(bits, page_points);
        let limits = renderer.ctx.device.limits();
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let max_slots = max_binding / (u64::from(slot_attr_words) * 4) - 1;
        let capacity = (pool_bytes / slot_bytes).clamp(1, max_slots) as usize;
        let device = &renderer.ctx.device;
        let buffer = |label: &str, words: u32| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (capacity as u64 + 1) * u64::from(words) * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let positions = buffer("page pool positions", slot_pos_words);
        let attrs = buffer("page pool attributes", slot_attr_words);
        // The reserved last slot: the top node at its centroid (zero words, scale 0).
        let mut top = Vec::new();
        packer.push(&file, 0, 0, 1, &mut top)?;
        renderer.ctx.queue.write_buffer(
            &attrs,
            capacity as u64 * u64::from(slot_attr_words) * 4,
            bytemuck::cast_slice(&top),
        );
        let species = storage_buffer(device, "species", bytemuck::cast_slice(&packer.species));

        let (req_tx, req_rx) = channel::<Vec<(f32, PageId)>>();
        let (res_tx, res_rx) = channel::<LoadedPage>();
        let stop = Arc::new(AtomicBool::new(false));
        let loader_stop = stop.clone();
        let loader_file = file.clone();
        let loader_page_points = page_points;
        let loader_packer = packer.clone();
        let loader = std::thread::Builder::new()
            .name("mdlod-page-loader".into())
            .spawn(move || {
                run_loader(&req_rx, &res_tx, &loader_stop, |id| {
                    load_page(&loader_file, id, loader_page_points, &loader_packer)
                })
            })
            .map_err(|e| RenderError::Gpu(format!("cannot start the page loader: {e}")))?;
        Ok(StreamingRenderer {
            renderer,
            file,
            capacity,
            page_points,
            slot_pos_words,
            slot_attr_words,
            positions,
            attrs,
            species,
            packer,
            look: look.clone(),
            slots: vec![None; capacity],
            resident: PageMap::default(),
            pending: PageSet::default(),
            unused: 0,
            frame: 0,
            evicted_total: 0,
            requests: Some(req_tx),
            loaded: res_rx,
            stop,
            backlog: Vec::new(),
            loader: Some(loader),
            last_view: None,
            complete_cut: None,
            staged: SlotWrites::default(),
        })
    }

    /// Pages the pool holds.
    pub fn capacity_pages(&self) -> usize {
        self.capacity
    }

    /// Total pages of the file (levels 1 and below).
    pub fn file_pages(&self) -> u64 {
        self.file.levels()[1..]
            .iter()
            .map(|l| l.point_count.div_ceil(u64::from(self.page_points)))
            .sum()
    }

    /// Waits until every requested page has arrived (or `timeout` passes); they are
    /// installed by the next frame.
    pub fn wait_for_loads(&mut self, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        let mut arrived = Vec::new();
        let outstanding = self.pending.len().saturating_sub(self.backlog.len());
        while arrived.len() < outstanding {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.loaded.recv_timeout(left) {
                Ok(p) => arrived.push(p),
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => break,
            }
        }
        self.backlog.extend(arrived);
    }

    /// Installs one arrived page; `victims` holds this frame's eviction candidates once
    /// the pool is full (the next to evict last).
    fn install(
        &mut self,
        page: LoadedPage,
        stats: &mut StreamStats,
        victims: &mut Option<Vec<u32>>,
    ) -> Result<(), RenderError> {
        self.pending.remove(&page.id);
        if let Some(e) = page.error {
            return Err(e);
        }
        if self.resident.contains_key(&page.id) {
            return Ok(());
        }
        let slot = if (self.unused as usize) < self.capacity {
            self.unused += 1;
            self.unused as usize - 1
        } else {
            // Least recently used among the slots the previous frame did not use,
            // ties to the lowest slot: the candidates are listed and sorted once per
            // frame (those installed meanwhile are used by this frame, so the list
            // only shrinks), instead of a scan of the pool per page.
            let frame = self.frame;
            let victims = victims.get_or_insert_with(|| {
                let mut v: Vec<(u64, u32)> = self
                    .slots
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| s.map(|s| (s.last_used, i as u32)))
                    .filter(|&(last_used, _)| last_used + 1 < frame)
                    .collect();
                v.sort_unstable_by(|a, b| b.cmp(a));
                v.into_iter().map(|(_, i)| i).collect()
            });
            let Some(s) = victims.pop() else {
                return Ok(()); // No room now; asked for again if still wanted.
            };
            if let Some(old) = self.slots[s as usize] {
                self.resident.remove(&old.page);
            }
            stats.evicted += 1;
            self.evicted_total += 1;
            s as usize
        };
        self.stage(slot as u32, &page);
        // Requested by the previous frame: as recently used as its pages.
        self.slots[slot] = Some(Slot {
            page: page.id,
            last_used: self.frame,
        });
        self.resident.insert(page.id, slot as u32);
        stats.installed += 1;
        Ok(())
    }

    /// Adds a page's words to the run of consecutive slots written in one go (each slot
    /// padded to its full size), writing the run out first when the page does not
    /// continue it or the run is large.
    fn stage(&mut self, slot: u32, page: &LoadedPage) {
        let w = &mut self.staged;
        if w.slots > 0 && (slot != w.first + w.slots || w.attrs.len() * 4 >= STAGED_BYTES) {
            self.write_staged();
        }
        let w = &mut self.staged;
        if w.slots == 0 {
            w.first = slot;
        }
        w.slots += 1;
        let (pos_end, attr_end) = (
            w.slots as usize * self.slot_pos_words as usize,
            w.slots as usize * self.slot_attr_words as usize,
        );
        w.positions.extend_from_slice(&page.positions);
        w.positions.resize(pos_end, 0);
        w.attrs.extend_from_slice(&page.attrs);
        w.attrs.resize(attr_end, 0);
    }

    /// Writes the staged run of slots to the pool's buffers.
    fn write_staged(&mut self) {
        let w = &mut self.staged;
        if w.slots == 0 {
            return;
        }
        let queue = &self.renderer.ctx.queue;
        queue.write_buffer(
            &self.positions,
            u64::from(w.first) * u64::from(self.slot_pos_words) * 4,
            bytemuck::cast_slice(&w.positions),
        );
        queue.write_buffer(
            &self.attrs,
            u64::from(w.first) * u64::from(self.slot_attr_words) * 4,
            bytemuck::cast_slice(&w.attrs),
        );
        w.slots = 0;
        w.positions.clear();
        w.attrs.clear();
    }

    /// Draws one frame of `camera`'s view as spheres with what is resident, installs what
    /// arrived and requests what is missing. Repeat with a still view until
    /// [`StreamStats::complete`]. Other passes draw a [`Self::prepare`]d cut through
    /// [`CutSource`].
    pub fn render(
        &mut self,
        camera: &Camera,
        traversal: &TraversalSettings,
        settings: &FrameSettings,
    ) -> Result<(RenderedFrame, DrawList, StreamStats), RenderError> {
        if self.packer.style() != PackStyle::Spheres || self.look != settings.style {
            return Err(RenderError::InvalidOptions(
                "this pool's pages were packed for another style than the frame's".into(),
            ));
        }
        let (draw, stats) = self.prepare(camera, traversal)?;
        let frame = self.renderer.render_from(self, camera, &draw, settings)?;
        Ok((frame, draw, stats))
    }

    /// The pages' packing and look (a pool serves the passes of one style).
    pub fn style(&self) -> (PackStyle, &PointStyle) {
        (self.packer.style(), &self.look)
    }

    /// One frame's bookkeeping without drawing: installs the pages that arrived, chooses
    /// the cut of `camera`'s view from what is resident, and requests what is missing.
    /// The cut's points are then bound with [`CutSource::bind`] until the next call.
    pub fn prepare(
        &mut self,
        camera: &Camera,
        traversal: &TraversalSettings,
    ) -> Result<(DrawList, StreamStats), RenderError> {
        self.frame += 1;
        let mut stats = StreamStats {
            frame: self.frame,
            capacity_pages: self.capacity,
            ..Default::default()
        };
        let mut arrived: Vec<LoadedPage> = std::mem::take(&mut self.backlog);
        arrived.extend(self.loaded.try_iter());
        let mut victims = None;
        // Every arrived page is taken off the pending list and the staged ones written
        // also when one is bad, so the pool stays consistent for the next frame.
        let mut bad = None;
        for page in arrived {
            if let Err(e) = self.install(page, &mut stats, &mut victims) {
                bad.get_or_insert(e);
            }
        }
        self.write_staged();
        if let Some(e) = bad {
            return Err(e);
        }

        let file = self.file.clone();
        // The cut, on every core, opening the nodes whose pages are all resident; then
        // the nodes it asked to open are answered again in one order (those drawn
        // first, then largest first) to mark the pages in use and request the missing
        // ones within the pool's capacity.
        let pages_resident = PagesResident {
            page_points: self.page_points,
            resident: &self.resident,
        };
        let view = (camera.clone(), *traversal);
        let still = self.last_view.as_ref() == Some(&view);
        if !still {
            self.complete_cut = None;
        }
        // Once the still view's complete cut is known, the frame's traversal starts at
        // the error that cut was drawn at (coarser than asked when the occlusion
        // traversal restarted to meet the budget): with its pages resident it then makes
        // the complete cut's decisions, instead of a finer cut that defers nodes, which
        // the pool, holding the complete cut, would never have room for.
        let frame_traversal = match &self.complete_cut {
            Some(c) => TraversalSettings {
                error_px: crate::traversal::error_of_restarts(traversal.error_px, c.restarts),
                ..*traversal
            },
            None => *traversal,
        };
        let (mut draw, asked) = traverse_shared(camera, &file, &frame_traversal, &pages_resident);
        if let Some(c) = &self.complete_cut {
            // Started past the restarts: they still limited it.
            draw.restarts += c.restarts;
            draw.budget_limited |= c.restarts > 0;
        }
        file.node_error()?;
        let mut residency = PoolResidency {
            page_points: self.page_points,
            resident: &self.resident,
            slots: &mut self.slots,
            frame: self.frame,
            capacity: self.capacity,
            used: PageSet::default(),
            wanted: Vec::new(),
            pool_limited: false,
        };
        let (drawn, missing): (Vec<_>, Vec<_>) = asked
            .into_iter()
            .partition(|&(id, _)| pages_resident.resident(&file, id));
        // Look ahead once per still view: on its second frame, the pages of the
        // complete cut (the traversal as if everything were resident) are requested
        // at once, largest first within the pool. Without it each frame could ask only
        // for the children of nodes it could draw, one level per frame (15 frames, most
        // of them traversals, at 2×10^8 particles). The complete cut's nodes are kept
        // and marked first on every later frame of the view, before those the frame
        // draws: a coarser cut drawn on the way (under a point budget it may open nodes
        // the complete cut does not) then never keeps the complete cut's pages out of a
        // pool that holds them.
        let unfinished = !missing.is_empty() || draw.deferred_nodes > 0;
        if still && self.complete_cut.is_none() && unfinished {
            let (list, complete) = traverse_shared(camera, &file, traversal, &EveryPage);
            file.node_error()?;
            self.complete_cut = Some(CompleteCut {
                restarts: list.restarts,
                nodes: complete,
            });
        }
        let mut limited = None;
        if let Some(c) = self.complete_cut.as_ref().filter(|_| unfinished) {
            for &(id, size) in &c.nodes {
                residency.can_open(&file, id, size);
                // Full, and a node refused: nothing more of the cut fits (a pool too
                // small for it would otherwise go through the whole cut every frame).
                if residency.pool_limited && residency.used.len() >= residency.capacity {
                    break;
                }
            }
            // The pool is limited when it cannot hold the complete cut, not when the
            // frame's own coarser nodes no longer fit beside it.
            limited = Some(residency.pool_limited);
        }
        for (id, size) in drawn.into_iter().chain(missing) {
            residency.can_open(&file, id, size);
        }
        if let Some(l) = limited {
            residency.pool_limited = l;
        }
        self.last_view = Some(view);
        let (used, mut wanted, pool_limited) = (
            residency.used.len(),
            residency.wanted,
            residency.pool_limited,
        );
        stats.used_pages = used;
        stats.pool_limited = pool_limited;

        // Requests, largest first.
        wanted.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut batch = Vec::new();
        for (size, id) in wanted {
            if self.pending.insert(id) {
                batch.push((size, id));
            }
        }
        stats.requested = batch.len();
        if !batch.is_empty() {
            if let Some(tx) = &self.requests {
                tx.send(batch)
                    .map_err(|_| RenderError::Gpu("the page loader stopped".into()))?;
            }
        }
        stats.pending = self.pending.len();
        stats.evicted_total = self.evicted_total;
        stats.resident_pages = self.resident.len();
        stats.complete = stats.requested == 0 && stats.pending == 0 && draw.deferred_nodes == 0;

        Ok((draw, stats))
    }

    /// The GPU ranges of a cut: each range split at page boundaries, pointing into
    /// the slots.
    fn ranges_of(&self, draw: &DrawList) -> Result<(Vec<RangeGpu>, Vec<u32>), RenderError> {
        let nodes = self.file.nodes();
        let last = self.file.level_count() - 1;
        let mut ranges = Vec::new();
        let mut point_range = Vec::new();
        let mut push = |r: RangeGpu, count: u32, ranges: &mut Vec<RangeGpu>| {
            let mut r = r;
            r.first_point = point_range.len() as u32;
            point_range.extend(std::iter::repeat_n(ranges.len() as u32, count as usize));
            ranges.push(r);
        };
        for d in &draw.ranges {
            if d.level == 0 {
                let r = RangeGpu {
                    base: nodes[0].centroid,
                    word_offset: self.capacity as u32 * self.slot_pos_words,
                    scale: [0.0; 3],
                    attr_offset: self.capacity as u32 * self.slot_attr_words,
                    kind: self.packer.kind(0, last),
                    ..Default::default()
                };
                push(r, 1, &mut ranges);
                continue;
            }
            let enc = &nodes[d.quant_node as usize];
            let kind = self.packer.kind(usize::from(d.level), last);
            let mut a = d.first;
            let end = d.first + d.count;
            while a < end {
                let page = a / self.page_points;
                let b = page_end(page, self.page_points, end);
                let id = PageId {
                    level: d.level,
                    page,
                };
                let slot = *self.resident.get(&id).ok_or_else(|| {
                    RenderError::Gpu(format!("page {id:?} drawn but not resident"))
                })?;
                let r = RangeGpu {
                    base: enc.centroid,
                    word_offset: slot * self.slot_pos_words,
                    scale: enc.quant_scale,
                    attr_offset: slot * self.slot_attr_words,
                    kind,
                    point_offset: a - page * self.page_points,
                    ..Default::default()
                };
                push(r, b - a, &mut ranges);
                a = b;
            }
        }
        Ok((ranges, point_range))
    }
}

impl CutSource for StreamingRenderer<'_> {
    fn style(&self) -> PackStyle {
        self.packer.style()
    }

    fn light_unit(&self) -> f32 {
        self.packer.light_unit()
    }

    fn value_scale(&self) -> Result<Option<crate::style::AttributeScale>, RenderError> {
        Ok(self.packer.value_scale().copied())
    }

    /// Batches within one storage binding each, counting the ranges after their split at
    /// page boundaries (`stream_batch_limits`).
    fn batch_lists(&self, draw: &DrawList) -> Option<Vec<DrawList>> {
        let (points, ranges) = self.renderer.batch_limits();
        let (points, ranges) = stream_batch_limits(points, ranges, self.page_points);
        Some(draw.batches(points, ranges)).filter(|b| b.len() > 1)
    }

    /// Binds the pool's pages for `draw`: the last [`StreamingRenderer::prepare`]d cut,
    /// or any reordering or subset of its points (every page it touches is resident).
    fn bind(&self, draw: &DrawList) -> Result<BoundCut, RenderError> {
        let (ranges, point_range) = self.ranges_of(draw)?;
        let (max_points, max_ranges) = self.renderer.batch_limits();
        if ranges.len() > max_ranges || point_range.len() > max_points as usize {
            return Err(RenderError::InvalidOptions(format!(
                "a batch of {} points in {} ranges is more than one storage binding holds \
                 ({max_points} points, {max_ranges} ranges): bind it in batches",
                point_range.len(),
                ranges.len()
            )));
        }
        let device = &self.renderer.ctx.device;
        let ranges_buf = storage_buffer(device, "ranges", bytemuck::cast_slice(&ranges));
        let point_range_buf =
            storage_buffer(device, "point_range", bytemuck::cast_slice(&point_range));
        let buffers = self.renderer.sphere_pass().bind(
            device,
            &SphereInputs {
                positions: &self.positions,
                attrs: &self.attrs,
                ranges: &ranges_buf,
                point_range: &point_range_buf,
                species: &self.species,
            },
            point_range.len() as u32,
        );
        Ok(BoundCut {
            buffers,
            position_bits: self.file.position_bits(),
            species_count: self.packer.species.len() as u32,
            data_bytes: self.positions.size()
                + self.attrs.size()
                + ranges_buf.size()
                + point_range_buf.size()
                + self.species.size(),
        })
    }
}

impl Drop for StreamingRenderer<'_> {
    fn drop(&mut self) {
        // The loader stops at its next page instead of loading the rest of its queue.
        self.stop.store(true, Ordering::Relaxed);
        self.requests.take();
        if let Some(h) = self.loader.take() {
            let _ = h.join();
        }
    }
}

/// The points and ranges of one batch of a pool's cut such that, once its ranges are
/// split at page boundaries, the batch stays within `max_points` points and `max_ranges`
/// ranges: a range of `c` points becomes at most `c / page_points + 2` pieces, so a batch
/// of `p` points in `r` ranges has at most `p / page_points + 2 r` of them.
fn stream_batch_limits(max_points: u32, max_ranges: usize, page_points: u32) -> (u32, usize) {
    let pp = page_points.max(1) as usize;
    let half = max_ranges / 2;
    let points = max_points.min(u32::try_from(half.saturating_mul(pp)).unwrap_or(u32::MAX));
    let ranges = (max_ranges - points as usize / pp) / 2;
    (points.max(1), ranges.max(1))
}

struct PoolResidency<'a> {
    page_points: u32,
    resident: &'a PageMap<u32>,
    slots: &'a mut Vec<Option<Slot>>,
    frame: u64,
    capacity: usize,
    used: PageSet,
    wanted: Vec<(f32, PageId)>,
    pool_limited: bool,
}

/// Where the part of a range ending at `end` that lies in page `page` ends: the page's
/// end or `end`, whichever is first (a level's last page may end past `u32::MAX`).
fn page_end(page: u32, page_points: u32, end: u32) -> u32 {
    let page_end = (u64::from(page) + 1) * u64::from(page_points);
    u32::try_from(page_end).map_or(end, |p| p.min(end))
}

/// The pages holding the children of node `id`.
fn pages_of(file: &MdlodFile, id: u32, page_points: u32) -> impl Iterator<Item = PageId> + Clone {
    let n = &file.nodes()[id as usize];
    let level = n.level + 1;
    let first_page = n.child_first / page_points;
    let last_page = (n.child_first + n.child_count - 1) / page_points;
    (first_page..=last_page).map(move |page| PageId { level, page })
}

/// The look-ahead's residency: every node may open, and the traversal lists them all.
struct EveryPage;

impl SharedResidency for EveryPage {
    fn resident(&self, _file: &MdlodFile, _id: u32) -> bool {
        true
    }
}

/// What the parallel traversal asks: are all of a node's child pages in the pool?
struct PagesResident<'a> {
    page_points: u32,
    resident: &'a PageMap<u32>,
}

impl SharedResidency for PagesResident<'_> {
    fn resident(&self, file: &MdlodFile, id: u32) -> bool {
        pages_of(file, id, self.page_points).all(|p| self.resident.contains_key(&p))
    }
}

impl Residency for PoolResidency<'_> {
    fn can_open(&mut self, file: &MdlodFile, id: u32, size_px: f32) -> bool {
        let pages = pages_of(file, id, self.page_points);
        let new = pages.clone().filter(|p| !self.used.contains(p)).count();
        if self.used.len() + new > self.capacity {
            self.pool_limited = true;
            return false;
        }
        let mut all = true;
        for p in pages {
            self.used.insert(p);
            match self.resident.get(&p) {
                Some(&slot) => {
                    if let Some(s) = &mut self.slots[slot as usize] {
                        s.last_used = self.frame;
                    }
                }
                None => {
                    all = false;
                    self.wanted.push((size_px, p));
                }
            }
        }
        all
    }

    fn restart(&mut self) {
        self.used.clear();
        self.wanted.clear();
        self.pool_limited = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn page(level: u8, page: u32) -> PageId {
        PageId { level, page }
    }

    fn loaded(id: PageId) -> LoadedPage {
        LoadedPage {
            id,
            positions: vec![],
            attrs: vec![],
            error: None,
        }
    }

    #[test]
    fn the_loader_takes_later_requests_into_one_queue_largest_first() {
        let (req_tx, req_rx) = channel();
        let (res_tx, res_rx) = channel();
        // Two frames' requests queued before the loader starts: the second frame's
        // larger page goes ahead of the first frame's smaller ones; equal sizes keep
        // the order they were asked in.
        req_tx
            .send(vec![
                (8.0, page(2, 0)),
                (2.0, page(3, 0)),
                (2.0, page(3, 1)),
            ])
            .unwrap();
        req_tx
            .send(vec![(30.0, page(1, 0)), (2.0, page(3, 2))])
            .unwrap();
        drop(req_tx);
        run_loader(&req_rx, &res_tx, &AtomicBool::new(false), loaded);
        let order: Vec<PageId> = res_rx.try_iter().map(|p| p.id).collect();
        assert_eq!(
            order,
            [page(1, 0), page(2, 0), page(3, 0), page(3, 1), page(3, 2)]
        );
    }

    #[test]
    fn a_stopped_loader_does_not_load_the_rest_of_its_queue() {
        let (req_tx, req_rx) = channel();
        let (res_tx, res_rx) = channel();
        req_tx
            .send((0..1000).map(|i| (1.0, page(1, i))).collect())
            .unwrap();
        let stop = AtomicBool::new(false);
        let count = std::cell::Cell::new(0);
        // The renderer is dropped while the third page loads.
        run_loader(&req_rx, &res_tx, &stop, |id| {
            count.set(count.get() + 1);
            if count.get() == 3 {
                stop.store(true, Ordering::Relaxed);
            }
            loaded(id)
        });
        assert_eq!(count.get(), 3);
        assert_eq!(res_rx.try_iter().count(), 2);
        // A receiver gone stops it too.
        let (req_tx, req_rx) = channel();
        let (res_tx, res_rx) = channel();
        req_tx
            .send(vec![(1.0, page(1, 0)), (1.0, page(1, 1))])
            .unwrap();
        drop(res_rx);
        let count = std::cell::Cell::new(0);
        run_loader(&req_rx, &res_tx, &AtomicBool::new(false), |id| {
            count.set(count.get() + 1);
            loaded(id)
        });
        assert_eq!(count.get(), 1);
    }

    #[test]
    fn page_ends_do_not_overflow_near_the_last_point_index() {
        assert_eq!(page_end(0, 64, 100), 64);
        assert_eq!(page_end(1, 64, 100), 100);
        // The last page of a level holding nearly 2^32 points.
        let last = u32::MAX / 64;
        assert_eq!(page_end(last, 64, u32::MAX), u32::MAX);
        assert_eq!(page_end(last - 1, 64, u32::MAX), last * 64);
    }

    #[test]
    fn batches_of_a_pool_cut_fit_one_binding_once_split_at_pages() {
        // Every range of every batch split at 4-point pages, counted against the limits,
        // for ranges at all offsets and sizes.
        for (max_points, max_ranges, pp) in [(1000, 60, 4), (1000, 600, 64), (7, 3, 4), (1, 1, 4)] {
            let (points, ranges) = stream_batch_limits(max_points, max_ranges, pp);
            let mut draw = DrawList::default();
            let mut first = 0;
            for k in 0..500u32 {
                let count = 1 + (k * 37) % 29;
                draw.ranges.push(crate::traversal::DrawRange {
                    level: 1,
                    first: first + k % 3,
                    count,
                    quant_node: 0,
                });
                draw.points += u64::from(count);
                first += count + 5;
            }
            for b in draw.batches(points, ranges) {
                let pieces: u32 = b
                    .ranges
                    .iter()
                    .map(|r| (r.first + r.count - 1) / pp - r.first / pp + 1)
                    .sum();
                assert!(
                    b.points <= u64::from(max_points),
                    "{max_points} {max_ranges}"
                );
                assert!(
                    pieces as usize <= max_ranges,
                    "{pieces} pieces > {max_ranges} (limits {points}, {ranges})"
                );
            }
        }
    }
}
