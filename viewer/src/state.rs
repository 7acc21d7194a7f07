//! What the viewer shows, as plain data: the camera, the render mode and its settings,
//! the lights and the timestep. Every input, from the mouse, the keyboard, the panel or a
//! script, becomes an [`Action`] applied here, so the whole interaction logic is tested
//! without a window. [`ViewerState::render_options`] turns the state into the same
//! [`RenderOptions`] `mdlod render` uses, which is why a viewer screenshot and a headless
//! render of the same view and settings are the same pixels.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use mdlod_render::camera::{Bounds, Camera, Projection};
use mdlod_render::glam::Vec3;
use mdlod_render::sndf::{Binning, EnvironmentMap, Explorer, ShadeLights, TransferImage};
use mdlod_render::{
    density::DensitySettings, ColourMap, Lighting, PointStyle, RenderMode, RenderOptions,
    SpeciesStyle, ViewSpec,
};
use serde::{Deserialize, Serialize};

/// How the view is drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Ray-cast spheres, one sample per pixel (`spheres`, as `mdlod render` names it, is
    /// accepted too).
    #[default]
    #[serde(alias = "spheres")]
    Standard,
    /// Ray-cast spheres with jittered supersampling once the view is still.
    Supersampled,
    /// S-NDFs sampled progressively while the view is still, shaded from the S-NDFs:
    /// changing the lights re-shades without touching the particles.
    Sndf,
    /// Additive, flux-preserving splats, tone mapped.
    Splat,
    /// The image-space density volume.
    Density,
    /// The density's iso-surface.
    Iso,
}

impl Mode {
    pub const ALL: [Mode; 6] = [
        Mode::Standard,
        Mode::Supersampled,
        Mode::Sndf,
        Mode::Splat,
        Mode::Density,
        Mode::Iso,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Mode::Standard => "standard",
            Mode::Supersampled => "supersampled",
            Mode::Sndf => "S-NDF",
            Mode::Splat => "splat",
            Mode::Density => "density",
            Mode::Iso => "iso-surface",
        }
    }
}

/// A directional light: the direction towards it in view space (x right, y up, z towards
/// the viewer) and its linear RGB colour.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Light {
    pub direction: [f32; 3],
    #[serde(default = "white")]
    pub colour: [f32; 3],
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

/// Everything but the camera and the timestep.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub mode: Mode,
    /// Supersampled mode: samples per pixel of the refined image.
    pub spp: u32,
    /// S-NDF mode: rays per texel to refine to.
    pub sndf_iterations: u32,
    pub bins: u32,
    /// Screen error (px) of the refined image.
    pub error_px: f32,
    /// Most spheres in one frame.
    pub budget: u64,
    /// Frame time to hold while the view moves (ms): the cut coarsens until it does.
    pub target_frame_ms: f32,
    /// sRGB background.
    pub background: [f32; 3],
    pub lights: Vec<Light>,
    pub ambient: f32,
    pub diffuse: f32,
    /// Blinn-Phong highlight weight; 0 is Lambert only.
    pub specular: f32,
    pub shininess: f32,
    /// S-NDF mode: colour the normals by the explorer pattern (this many slices around a
    /// central disk) instead of lighting them.
    pub explorer: Option<u32>,
    pub explorer_disk_deg: f32,
    pub explorer_tolerance_deg: f32,
    /// Density and iso modes.
    pub iso_value: f32,
    pub density_max: f32,
    pub absorption: f32,
    /// Sphere and S-NDF modes: species colours and visibility, radius scale, colour map.
    pub style: PointStyle,
    /// S-NDF mode: a painted transfer function over the normal disk (before the explorer
    /// and the lights), and an environment map's light.
    pub transfer: Option<Arc<TransferImage>>,
    pub environment: Option<Arc<EnvironmentMap>>,
}

impl Default for Settings {
    fn default() -> Self {
        let l = Lighting::default();
        Settings {
            mode: Mode::Standard,
            spp: 8,
            sndf_iterations: 64,
            bins: 8,
            error_px: 1.0,
            budget: 4_000_000,
            target_frame_ms: 33.0,
            background: [1.0; 3],
            lights: vec![Light {
                direction: l.direction_view.to_array(),
                colour: [1.0; 3],
            }],
            ambient: l.ambient,
            diffuse: l.diffuse,
            specular: l.specular,
            shininess: l.shininess,
            explorer: None,
            explorer_disk_deg: 20.0,
            explorer_tolerance_deg: 3.0,
            iso_value: 0.3,
            density_max: 0.8,
            absorption: 0.5,
            style: PointStyle::default(),
            transfer: None,
            environment: None,
        }
    }
}

impl Settings {
    /// The S-NDF shading (all lights, colours, BRDF and explorer); relighting changes only
    /// this.
    pub fn shade_lights(&self) -> ShadeLights {
        ShadeLights {
            ambient: self.ambient,
            lights: self
                .lights
                .iter()
                .map(|l| (Vec3::from(l.direction).normalize_or_zero(), l.colour))
                .collect(),
            diffuse: self.diffuse,
            specular: self.specular,
            shininess: self.shininess,
            environment: self.environment.as_deref().cloned(),
            explorer: self.explorer.map(|slices| {
                Explorer::new(
                    slices.max(1),
                    self.explorer_disk_deg,
                    self.explorer_tolerance_deg,
                )
            }),
            transfer: self.transfer.as_deref().cloned(),
        }
    }

    /// The sphere renderer's lighting: its one light is the first of the list, with its
    /// colour; with every light removed, the ambient alone, as the S-NDFs shade then
    /// (the spheres fell back to the default white light).
    pub fn sphere_lighting(&self) -> Lighting {
        let direction = self
            .lights
            .first()
            .map(|l| Vec3::from(l.direction).normalize_or_zero())
            .filter(|d| *d != Vec3::ZERO)
            .unwrap_or(Lighting::default().direction_view);
        Lighting {
            direction_view: direction,
            colour: self.lights.first().map_or([0.0; 3], |l| l.colour),
            ambient: self.ambient,
            diffuse: self.diffuse,
            specular: self.specular,
            shininess: self.shininess,
        }
    }
}

/// A script's actions from its text, a JSON array of [`Action`]s. An action that does not
/// parse is named by its place in the list, its name and the line it starts on (serde's
/// own place is where the object ends, which reads as the line after it).
pub fn parse_script(text: &str) -> Result<Vec<Action>, String> {
    let values: Vec<serde_json::Value> = serde_json::from_str(text).map_err(|e| {
        if e.is_data() {
            format!("a script is a list of actions, [{{\"action\": ...}}, ...]: {e}")
        } else {
            e.to_string()
        }
    })?;
    // Where each element of the top-level array starts: its opening brace at depth 1.
    let mut starts = Vec::with_capacity(values.len());
    let (mut depth, mut in_string, mut escaped, mut line) = (0usize, false, false, 1usize);
    for c in text.chars() {
        match c {
            '\n' => line += 1,
            _ if in_string => {}
            '{' | '[' => {
                if depth == 1 {
                    starts.push(line);
                }
                depth += 1;
            }
            '}' | ']' => depth = depth.saturating_sub(1),
            _ => {}
        }
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
        } else if c == '"' {
            in_string = true;
        }
    }
    values
        .into_iter()
        .enumerate()
        .map(|(i, v)| {
            let name = v
                .get("action")
                .and_then(|a| a.as_str())
                .map_or("no \"action\"".to_string(), str::to_owned);
            let at = starts
                .get(i)
                .map_or(String::new(), |l| format!(", line {l}"));
            serde_json::from_value::<Action>(v).map_err(|e| format!("action {i} ({name}{at}): {e}"))
        })
        .collect()
}

/// One input, whatever its source (mouse, keys, panel, script). Scripts are JSON arrays
/// of these, e.g. `{"action": "orbit", "dx": 120, "dy": 0}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "action", rename_all = "snake_case", deny_unknown_fields)]
pub enum Action {
    /// Orbit as a mouse drag of (dx, dy) pixels does.
    Orbit {
        dx: f32,
        dy: f32,
    },
    /// Pan as a drag of (dx, dy) pixels with the right button does.
    Pan {
        dx: f32,
        dy: f32,
    },
    /// Move closer by this factor (2: twice as close).
    Zoom {
        factor: f32,
    },
    /// Fit the data in view.
    Fit,
    /// Perspective or orthographic projection.
    Projection {
        orthographic: bool,
    },
    Mode {
        mode: Mode,
    },
    /// Set light `index`'s direction (view space).
    Light {
        index: usize,
        direction: [f32; 3],
    },
    /// Rotate light `index` as a drag of (dx, dy) pixels on the light widget does.
    DragLight {
        index: usize,
        dx: f32,
        dy: f32,
    },
    AddLight {
        light: Light,
    },
    RemoveLight {
        index: usize,
    },
    /// Set light `index`'s colour (linear RGB), keeping its place in the list (the
    /// sphere modes use the first light).
    LightColour {
        index: usize,
        colour: [f32; 3],
    },
    /// Lambert only (`specular` 0) or Blinn-Phong with this weight and exponent.
    Brdf {
        specular: f32,
        shininess: f32,
    },
    /// The S-NDF explorer pattern with this many slices, or none; optionally the
    /// central disk's angular radius and the border between slices (degrees).
    Explorer {
        slices: Option<u32>,
        #[serde(default)]
        disk_deg: Option<f32>,
        #[serde(default)]
        tolerance_deg: Option<f32>,
    },
    /// S-NDF mode: paint on the normal disk (x right, y up, in [-1, 1]) with a round
    /// brush of this radius; the painted disk then colours the normals instead of the
    /// lights.
    Paint {
        x: f32,
        y: f32,
        radius: f32,
        colour: [f32; 3],
    },
    /// Back to the lights from a painted disk.
    ClearPaint,
    /// An environment map (equirectangular PNG, view space) adding its Lambert light, or
    /// none.
    Environment {
        path: Option<PathBuf>,
    },
    /// Go to timestep `index` (of the data set's frames).
    Frame {
        index: usize,
    },
    /// Step this many timesteps (wrapping).
    Step {
        delta: i64,
    },
    ScreenError {
        px: f32,
    },
    /// A species' colour (linear RGB), by name.
    SpeciesColour {
        name: String,
        colour: [f32; 3],
    },
    /// Show or hide a species' particles, by name.
    SpeciesVisible {
        name: String,
        visible: bool,
    },
    /// Multiply every radius.
    RadiusScale {
        scale: f32,
    },
    /// Colour by the scalar attribute through this map, or by species.
    ColourMap {
        map: Option<ColourMap>,
    },
    /// Which of the data's attributes colours (and lights splats): `None` the first.
    Attribute {
        name: Option<String>,
    },
    /// S-NDF mode: rays per texel to refine to.
    SndfIterations {
        n: u32,
    },
    /// Supersampled mode: samples per pixel.
    Spp {
        n: u32,
    },
    TargetFrameMs {
        ms: f32,
    },
    /// Write the camera as a view file.
    SaveView {
        path: PathBuf,
    },
    LoadView {
        path: PathBuf,
    },
    /// Write what the window shows once the view is refined (no size), or render the
    /// current view and settings at this size through the headless path.
    Screenshot {
        path: PathBuf,
        #[serde(default)]
        width: Option<u32>,
        #[serde(default)]
        height: Option<u32>,
    },
    /// S-NDF mode: write the S-NDFs refined so far (with the camera) as a `.sndf` file,
    /// once refinement is done.
    SaveSndf {
        path: PathBuf,
    },
    /// Wait until the view is refined.
    WaitStill,
    /// Keep the window as it is for this many seconds (demonstrations, captures).
    Pause {
        seconds: f32,
    },
    Quit,
}

/// Which parts of the state an action changed, so that the viewer redraws only what must
/// be: the S-NDFs survive a lighting change.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Changed {
    /// The camera, the timestep, the mode or a setting the particles are drawn with.
    pub scene: bool,
    /// The lights or the BRDF only.
    pub lighting: bool,
}

/// Degrees of orbit per pixel dragged.
pub const ORBIT_DEG_PER_PX: f32 = 0.3;
/// Light widget: degrees per pixel dragged.
pub const LIGHT_DEG_PER_PX: f32 = 0.5;
/// Zooming keeps the camera's distance between these multiples of the data's bounding
/// radius: further out every render would fail (an infinite distance), further in the
/// distance would shrink to a denormal.
pub const ZOOM_RANGE: (f32, f32) = (1e-4, 1e4);

/// The viewer's state.
#[derive(Clone, Debug)]
pub struct ViewerState {
    pub camera: Camera,
    pub settings: Settings,
    /// The data set's frames (one for a single file) and the one shown.
    pub frames: Vec<FrameInfo>,
    pub frame: usize,
    /// The shown frame's bounds (for fitting and zoom limits).
    pub bounds: Bounds,
    /// The boxes that frame the shown frame's data where `mdlod render` fits it (its
    /// clusters; [`crate::framing`]); empty until the render thread reports them, when
    /// the bounds alone frame it.
    pub framing: Vec<mdlod_render::Framed>,
    /// Each frame's bounds, once known (the render thread reports them as it opens the
    /// frames).
    pub frame_bounds: Vec<Option<Bounds>>,
    /// The window's image size (pixels).
    pub size: [u32; 2],
    /// The data's species (name, linear colour), for the panel.
    pub species: Vec<(String, [f32; 3])>,
    /// Every attribute the data keeps (the first, then further ones), for the panel's
    /// colouring by the attribute and its choice of which.
    pub attributes: Vec<String>,
    /// The target and distance of the last fit (the first view's included): a switch of
    /// projection before any pan fits again for the new one, at the same zoom, as a
    /// perspective fit's target lies off the data's centre (so that the projected box is
    /// centred), which would crop an orthographic view.
    fitted: Option<(Vec3, f32)>,
}

/// One timestep of a data set.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameInfo {
    pub path: PathBuf,
    pub timestep: Option<u64>,
}

impl ViewerState {
    pub fn new(frames: Vec<FrameInfo>, camera: Camera, bounds: Bounds, size: [u32; 2]) -> Self {
        let mut frame_bounds = vec![None; frames.len()];
        if let Some(b) = frame_bounds.first_mut() {
            *b = Some(bounds);
        }
        ViewerState {
            fitted: Some((camera.target, camera.distance)),
            camera,
            settings: Settings::default(),
            frames,
            frame: 0,
            bounds,
            framing: Vec::new(),
            frame_bounds,
            size,
            species: vec![],
            attributes: vec![],
        }
    }

    pub fn aspect(&self) -> f32 {
        self.size[0].max(1) as f32 / self.size[1].max(1) as f32
    }

    /// Applies one action; file actions (views, screenshots) are the caller's, and change
    /// nothing here except `LoadView`, whose camera the caller passes through
    /// [`ViewerState::set_camera`].
    pub fn apply(&mut self, action: &Action) -> Changed {
        let scene = Changed {
            scene: true,
            lighting: false,
        };
        let lighting = Changed {
            scene: false,
            lighting: true,
        };
        let s = &mut self.settings;
        match action {
            Action::Orbit { dx, dy } => {
                self.camera
                    .orbit(-dx * ORBIT_DEG_PER_PX, dy * ORBIT_DEG_PER_PX);
                scene
            }
            Action::Pan { dx, dy } => {
                self.camera.pan_px(*dx, *dy, self.size[1].max(1));
                scene
            }
            Action::Zoom { factor } => {
                if !(factor.is_finite() && *factor > 0.0) {
                    return Changed::default();
                }
                // At the data's own scale (it may span 10^-10 or 10^20).
                let r = self.bounds.fit_radius();
                let r = if r.is_finite() { r } else { 1.0 };
                let before = self.camera.distance;
                let d = (before / factor).clamp(ZOOM_RANGE.0 * r, ZOOM_RANGE.1 * r);
                if d == before || !d.is_finite() {
                    Changed::default()
                } else {
                    self.camera.distance = d;
                    scene
                }
            }
            Action::Fit => {
                let aspect = self.aspect();
                self.camera.fit_boxes(&self.bounds, &self.framing, aspect);
                self.fitted = Some((self.camera.target, self.camera.distance));
                scene
            }
            Action::Projection { orthographic } => {
                let unpanned = self.fitted.filter(|(t, _)| *t == self.camera.target);
                self.camera.projection = if *orthographic {
                    Projection::Orthographic
                } else {
                    Projection::Perspective
                };
                if let Some((_, distance)) = unpanned {
                    let zoom = self.camera.distance / distance;
                    let aspect = self.aspect();
                    self.camera.fit_boxes(&self.bounds, &self.framing, aspect);
                    self.fitted = Some((self.camera.target, self.camera.distance));
                    let d = self.camera.distance * zoom;
                    if d.is_finite() && d > 0.0 {
                        self.camera.distance = d;
                    }
                }
                scene
            }
            Action::Mode { mode } => {
                s.mode = *mode;
                scene
            }
            Action::Light { index, direction } => {
                let d = Vec3::from(*direction);
                match s.lights.get_mut(*index) {
                    Some(l) if d.is_finite() && d != Vec3::ZERO => {
                        l.direction = d.normalize().to_array();
                        lighting
                    }
                    _ => Changed::default(),
                }
            }
            Action::DragLight { index, dx, dy } => match s.lights.get_mut(*index) {
                Some(l) => {
                    l.direction = drag_direction(l.direction, *dx, *dy);
                    lighting
                }
                None => Changed::default(),
            },
            Action::AddLight { light } => {
                s.lights.push(*light);
                lighting
            }
            Action::RemoveLight { index } => {
                if *index < s.lights.len() {
                    s.lights.remove(*index);
                    lighting
                } else {
                    Changed::default()
                }
            }
            Action::LightColour { index, colour } => match s.lights.get_mut(*index) {
                Some(l) if colour.iter().all(|c| c.is_finite()) => {
                    l.colour = colour.map(|c| c.max(0.0));
                    lighting
                }
                _ => Changed::default(),
            },
            Action::Brdf {
                specular,
                shininess,
            } => {
                s.specular = specular.max(0.0);
                s.shininess = shininess.max(1.0);
                lighting
            }
            Action::Explorer {
                slices,
                disk_deg,
                tolerance_deg,
            } => {
                s.explorer = *slices;
                if let Some(d) = disk_deg.filter(|d| d.is_finite()) {
                    s.explorer_disk_deg = d.clamp(0.0, 90.0);
                }
                if let Some(t) = tolerance_deg.filter(|t| t.is_finite()) {
                    s.explorer_tolerance_deg = t.clamp(0.0, 45.0);
                }
                lighting
            }
            Action::Paint {
                x,
                y,
                radius,
                colour,
            } => {
                let t = s.transfer.get_or_insert_with(|| {
                    Arc::new(TransferImage {
                        width: PAINT_SIZE,
                        height: PAINT_SIZE,
                        colour: vec![[0.5; 3]; (PAINT_SIZE * PAINT_SIZE) as usize],
                    })
                });
                paint(Arc::make_mut(t), *x, *y, *radius, *colour);
                lighting
            }
            Action::ClearPaint => {
                if s.transfer.take().is_some() {
                    lighting
                } else {
                    Changed::default()
                }
            }
            Action::Frame { index } => {
                if *index < self.frames.len() && *index != self.frame {
                    self.go_to(*index);
                    scene
                } else {
                    Changed::default()
                }
            }
            Action::Step { delta } => {
                let n = self.frames.len() as i64;
                if n <= 1 {
                    return Changed::default();
                }
                self.go_to((self.frame as i64 + delta).rem_euclid(n) as usize);
                scene
            }
            Action::ScreenError { px } => {
                s.error_px = px.max(0.0);
                scene
            }
            Action::SpeciesColour { name, colour } => {
                style_of(&mut s.style, name).colour = Some(colour.map(|c| c.clamp(0.0, 1.0)));
                scene
            }
            Action::SpeciesVisible { name, visible } => {
                style_of(&mut s.style, name).hidden = !visible;
                scene
            }
            Action::RadiusScale { scale } => {
                if scale.is_finite() && *scale > 0.0 {
                    s.style.radius_scale = *scale;
                    scene
                } else {
                    Changed::default()
                }
            }
            Action::ColourMap { map } => {
                s.style.colour_map = *map;
                scene
            }
            Action::Attribute { name } => {
                s.style.attribute = name.clone();
                scene
            }
            Action::SndfIterations { n } => {
                s.sndf_iterations = (*n).max(1);
                scene
            }
            Action::Spp { n } => {
                s.spp = (*n).clamp(1, mdlod_render::renderer::MAX_SPP);
                scene
            }
            Action::TargetFrameMs { ms } => {
                s.target_frame_ms = ms.max(1.0);
                Changed::default()
            }
            Action::SaveView { .. }
            | Action::LoadView { .. }
            | Action::Screenshot { .. }
            | Action::SaveSndf { .. }
            | Action::Environment { .. }
            | Action::WaitStill
            | Action::Pause { .. }
            | Action::Quit => Changed::default(),
        }
    }

    /// Refuses a script's action whose values `mdlod render` would refuse (the window's
    /// own widgets clamp instead): `index` is the action's place in the script.
    pub fn check_script_action(&self, index: usize, action: &Action) -> Result<(), String> {
        let refuse = |what: String| Err(format!("{}: {what}", script_place(index, action)));
        let lights = self.settings.lights.len();
        let positive = |v: f32| v.is_finite() && v > 0.0;
        match action {
            Action::Light { index: i, .. }
            | Action::DragLight { index: i, .. }
            | Action::RemoveLight { index: i }
            | Action::LightColour { index: i, .. }
                if *i >= lights =>
            {
                refuse(format!("light index {i}, but there are {lights} light(s)"))
            }
            Action::Zoom { factor } if !positive(*factor) => {
                refuse(format!("zoom factor {factor} is not positive"))
            }
            Action::RadiusScale { scale } if !positive(*scale) => {
                refuse(format!("radius scale {scale} is not positive"))
            }
            // As render: 0 is allowed (every particle).
            Action::ScreenError { px } if !(px.is_finite() && *px >= 0.0) => {
                refuse(format!("screen error {px} px (must be 0 or more)"))
            }
            Action::Spp { n: 0 } => refuse("0 samples per pixel".into()),
            Action::SndfIterations { n: 0 } => refuse("0 S-NDF iterations".into()),
            // Known before any frame is drawn: the first frame's attributes (a later
            // frame without it fails when it is shown).
            Action::Attribute { name: Some(name) }
                if !self.attributes.is_empty()
                    && mdlod_format::reader::attribute_named(
                        &self
                            .attributes
                            .iter()
                            .map(String::as_str)
                            .collect::<Vec<_>>(),
                        name,
                    )
                    .is_none() =>
            {
                refuse(format!(
                    "no attribute {name:?}; the data has {}",
                    self.attributes.join(", ")
                ))
            }
            // A species no frame holds, where the one frame tells (a trajectory's later
            // frames may bring species the first lacks: a deposition).
            Action::SpeciesColour { name, .. } | Action::SpeciesVisible { name, .. }
                if self.frames.len() == 1
                    && !self.species.is_empty()
                    && !self.species.iter().any(|(s, _)| s == name) =>
            {
                refuse(format!(
                    "no species {name:?}; the data has {}",
                    self.species
                        .iter()
                        .map(|(s, _)| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            }
            Action::Frame { index: i } if *i >= self.frames.len() => refuse(format!(
                "frame {i}, but the data has {} frame(s)",
                self.frames.len()
            )),
            // Screenshots are PNG images, named so (as render's -o).
            Action::Screenshot { path, .. }
                if path
                    .extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| !e.eq_ignore_ascii_case("png")) =>
            {
                refuse(format!(
                    "{}: screenshots are PNG images: name it .png",
                    path.display()
                ))
            }
            Action::Screenshot { width, height, .. } => match (width, height) {
                (None, None) => Ok(()),
                (Some(w), Some(h)) if *w > 0 && *h > 0 => Ok(()),
                (Some(w), Some(h)) => refuse(format!("a {w}x{h} screenshot")),
                _ => {
                    let given = |v: &Option<u32>| v.map_or("none".to_string(), |v| v.to_string());
                    refuse(format!(
                        "width {} and height {}: give both or neither",
                        given(width),
                        given(height)
                    ))
                }
            },
            Action::Pause { seconds } if !(seconds.is_finite() && *seconds >= 0.0) => {
                refuse(format!("pause of {seconds} seconds (must be 0 or more)"))
            }
            // As `render --light` and `shade`: a direction, colours in 0..1, weights of 0
            // and more, the explorer's angles.
            Action::Light { direction, .. }
            | Action::AddLight {
                light: Light { direction, .. },
            } if !(direction.iter().all(|v| v.is_finite())
                && direction.iter().any(|&v| v != 0.0)) =>
            {
                refuse(format!("light direction {direction:?} points nowhere"))
            }
            Action::LightColour { colour, .. }
            | Action::AddLight {
                light: Light { colour, .. },
            }
            | Action::SpeciesColour { colour, .. }
            | Action::Paint { colour, .. }
                if !colour.iter().all(|v| (0.0..=1.0).contains(v)) =>
            {
                refuse(format!(
                    "colour {colour:?}: linear RGB, each value from 0 to 1"
                ))
            }
            Action::Brdf {
                specular,
                shininess,
            } if !(specular.is_finite() && *specular >= 0.0 && positive(*shininess)) => {
                refuse(format!(
                    "specular {specular} and shininess {shininess}: a weight of 0 or more and \
                     an exponent above 0"
                ))
            }
            Action::Explorer {
                slices: Some(0), ..
            } => refuse("an explorer of 0 slices".into()),
            Action::Explorer {
                disk_deg: Some(d), ..
            } if !(*d > 0.0 && *d <= 90.0) => {
                refuse(format!("explorer disk of {d}°: above 0, at most 90"))
            }
            Action::Explorer {
                tolerance_deg: Some(t),
                ..
            } if !(0.0..=45.0).contains(t) => {
                refuse(format!("explorer border of {t}°: from 0 to 45"))
            }
            Action::Paint { x, y, radius, .. }
                if !((-1.0..=1.0).contains(x) && (-1.0..=1.0).contains(y) && positive(*radius)) =>
            {
                refuse(format!(
                    "paint at ({x}, {y}) with radius {radius}: a point of the normal disk \
                     (x and y in -1..1) and a radius above 0"
                ))
            }
            Action::TargetFrameMs { ms } if !positive(*ms) => {
                refuse(format!("a target frame time of {ms} ms (must be above 0)"))
            }
            Action::ColourMap { map: Some(_) } if self.attributes.is_empty() => refuse(
                "the data keeps no attribute to colour by (`mdlod convert --attribute NAME` \
                 keeps one)"
                    .into(),
            ),
            _ => Ok(()),
        }
    }

    /// A camera of the user's (a view file loaded): kept as it is by projection switches.
    pub fn set_camera(&mut self, camera: Camera) {
        self.camera = camera;
        self.fitted = None;
    }

    /// Shows frame `index`, with its bounds when known (else the last frame's stand in
    /// until the render thread reports them).
    fn go_to(&mut self, index: usize) {
        if index != self.frame {
            // (The new frame's come with its bounds from the render thread.)
            self.framing.clear();
        }
        self.frame = index;
        if let Some(Some(b)) = self.frame_bounds.get(index) {
            self.bounds = *b;
        }
    }

    /// The render thread opened `path`, whose data has these bounds: fitting, loading a
    /// view and the zoom limits use them while that frame is shown.
    pub fn set_frame_bounds(
        &mut self,
        path: &Path,
        bounds: Bounds,
        boxes: Vec<mdlod_render::Framed>,
    ) {
        for (i, f) in self.frames.iter().enumerate() {
            if f.path == path {
                if let Some(b) = self.frame_bounds.get_mut(i) {
                    *b = Some(bounds);
                }
                if i == self.frame {
                    self.bounds = bounds;
                    self.framing = boxes.clone();
                }
            }
        }
    }

    /// Whether the timesteps can play: there is more than one.
    pub fn can_play(&self) -> bool {
        self.frames.len() > 1
    }

    /// The options of the refined image of the current view at `size`.
    pub fn render_options(&self, size: [u32; 2]) -> RenderOptions {
        let s = &self.settings;
        let mode = match s.mode {
            Mode::Standard | Mode::Supersampled => RenderMode::Spheres,
            Mode::Sndf => RenderMode::Sndf {
                iterations: s.sndf_iterations,
                bins: s.bins,
                binning: Binning::default(),
            },
            Mode::Splat => RenderMode::Splat {
                by_attribute: false,
            },
            Mode::Density | Mode::Iso => RenderMode::Density(DensitySettings {
                iso: (s.mode == Mode::Iso).then_some(s.iso_value),
                density_max: s.density_max,
                opacity: s.absorption,
                // "colour by" the attribute: the surface's or the volume's colours.
                colour_map: s.style.colour_map,
                ..Default::default()
            }),
        };
        let splat = matches!(s.mode, Mode::Splat | Mode::Density | Mode::Iso);
        RenderOptions {
            width: size[0].max(1),
            height: size[1].max(1),
            view: ViewSpec::Camera(self.camera.clone()),
            spp: if s.mode == Mode::Supersampled {
                s.spp.max(1)
            } else {
                1
            },
            error_px: s.error_px,
            budget: s.budget,
            // As `mdlod render` defaults: splats and the density volume on black.
            background: if (splat && s.mode == Mode::Splat) || s.mode == Mode::Density {
                [0.0; 3]
            } else {
                s.background
            },
            lighting: s.sphere_lighting(),
            mode,
            style: s.style.clone(),
            ..Default::default()
        }
    }

    /// The options of a quick frame while the view moves: one sample per pixel and the
    /// cut coarsened to `error_px` (in the window's pixels); S-NDF and supersampled modes
    /// show plain spheres. A coarse preview is drawn [`preview_divisor`] times smaller on
    /// each side, with the same cut (its error in the smaller image's pixels), and shown
    /// stretched over the window: it draws no detail finer than its error anyway, and
    /// costs a software driver a quarter or a sixteenth of the pixels. The S-MIP's
    /// previews (orthographic S-NDF views) keep the window's size, which its cached tiles
    /// are sampled at.
    pub fn interactive_options(&self, size: [u32; 2], error_px: f32) -> RenderOptions {
        let error_px = error_px.max(self.settings.error_px);
        let smip = matches!(self.settings.mode, Mode::Sndf)
            && self.camera.projection == mdlod_render::Projection::Orthographic;
        let divisor = if smip { 1 } else { preview_divisor(error_px) };
        let mut o = self.render_options(size.map(|n| n.div_ceil(divisor)));
        o.spp = 1;
        o.error_px = error_px / divisor as f32;
        // Orthographic S-NDF views pan and zoom over the S-MIP's cached tiles (the render
        // thread falls back to spheres for an orbit); perspective ones preview spheres.
        // The S-MIP keeps the settled screen error (a new one would start a new cache);
        // the render thread draws the sphere preview of an orbit at `error_px`
        // ([`ViewerState::sphere_preview_error`]).
        if matches!(o.mode, RenderMode::Sndf { .. }) {
            if self.camera.projection == mdlod_render::Projection::Orthographic {
                o.error_px = self.settings.error_px;
            } else {
                o.mode = RenderMode::Spheres;
            }
        }
        o
    }

    /// The screen error of a sphere preview at the adapted preview error `error_px`
    /// (never finer than the settled error): the error of the previews of
    /// [`ViewerState::interactive_options`], and of the spheres the render thread draws
    /// instead of an orthographic S-NDF view while it orbits.
    pub fn sphere_preview_error(&self, error_px: f32) -> f32 {
        error_px.max(self.settings.error_px)
    }
}

/// How many times smaller on each side a preview at screen error `error_px` (in the
/// window's pixels) is drawn: 1 below 4 px, 2 below 8 px, 4 from 8 px on, so that the
/// error always spans at least 2 of the smaller image's pixels.
pub fn preview_divisor(error_px: f32) -> u32 {
    if error_px >= 8.0 {
        4
    } else if error_px >= 4.0 {
        2
    } else {
        1
    }
}

/// The next preview error (in the window's pixels) after a preview drawn `divisor` times
/// smaller took `last_frame_ms`: [`adapt_error`], except that a finer error that would
/// draw at a smaller divisor (up to 16 times the pixels) is taken only where the frame
/// leaves room for that many more pixels; otherwise the error stays at the smallest
/// drawn at `divisor`. Without that, a preview whose finer divisor is too slow and whose
/// coarser one is fast would switch between the two every frame.
pub fn adapt_preview_error(
    current_px: f32,
    last_frame_ms: f32,
    target_ms: f32,
    finest_px: f32,
    divisor: u32,
) -> f32 {
    let next = adapt_error(current_px, last_frame_ms, target_ms, finest_px);
    let then = preview_divisor(next);
    if divisor > 1 && then < divisor {
        let pixels = ((divisor / then) as f32).powi(2);
        if last_frame_ms * pixels > target_ms {
            // The smallest error drawn at `divisor` (see `preview_divisor`).
            return next.max(2.0 * divisor as f32);
        }
    }
    next
}

/// The most the preview error adapts to while the previews are S-MIP views: the error at
/// which [`SMIP_MAX_COARSEN`] levels of coarsening are reached (the S-MIP coarsens no
/// further, so a larger error would change nothing but stay, for the next sphere
/// previews, far coarser than they need).
pub fn smip_preview_cap(finest_px: f32) -> f32 {
    finest_px.max(0.25) * (1u32 << SMIP_MAX_COARSEN) as f32
}

/// S-MIP levels an orthographic S-NDF preview is coarsened by at most.
pub const SMIP_MAX_COARSEN: u32 = 3;

/// The render requests sent and the replies taken: which image to show, whether the view
/// is settled, whether a frame is on its way, and the status message.
///
/// Request ids only increase. An image of a request overtaken by a newer one is still
/// shown (it is the nearest thing to the view) until the newer one answers; an image of
/// a request older than one already answered (by its image or an error) is stale and
/// is dropped.
#[derive(Clone, Debug, PartialEq)]
pub struct Requests {
    next_id: u64,
    /// The newest request sent and whether it was a preview.
    requested: Option<(u64, bool)>,
    /// The request of the image shown, and whether that image is refined.
    shown: Option<(u64, bool)>,
    /// The newest request answered (by an image or an error).
    answered: u64,
    /// The newest request that ended in an error.
    failed: Option<u64>,
    /// The status message, and the first request whose image clears it.
    message: Option<(String, u64)>,
}

impl Default for Requests {
    fn default() -> Self {
        Requests {
            next_id: 1,
            requested: None,
            shown: None,
            answered: 0,
            failed: None,
            message: None,
        }
    }
}

impl Requests {
    /// A new request, a preview or not: its id.
    pub fn send(&mut self, preview: bool) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        self.requested = Some((id, preview));
        id
    }

    /// The newest request and whether it is a preview.
    pub fn requested(&self) -> Option<(u64, bool)> {
        self.requested
    }

    /// An image of request `id` came: whether to show it (false for a stale one). A
    /// message older than the request clears (the view recovered, or moved on).
    pub fn image(&mut self, id: u64, refined: bool) -> bool {
        if id < self.answered {
            return false;
        }
        self.answered = id;
        self.shown = Some((id, refined));
        if self.message.as_ref().is_some_and(|(_, clear)| id >= *clear) {
            self.message = None;
        }
        true
    }

    /// Request `id` failed with `message`: returns whether it is the newest request,
    /// which then counts as finished (the view gets no further).
    pub fn error(&mut self, id: u64, message: String) -> bool {
        self.message = Some((message, id.saturating_add(1)));
        self.answered = self.answered.max(id);
        let current = self.requested.is_some_and(|(r, _)| r == id);
        if current {
            self.failed = Some(id);
        }
        current
    }

    /// A message about no request (a file written or not): it stays until an image of a
    /// request sent after it comes.
    pub fn note(&mut self, message: String) {
        self.message = Some((message, self.next_id));
    }

    pub fn message(&self) -> Option<&str> {
        self.message.as_ref().map(|(m, _)| m.as_str())
    }

    /// The newest request is done: its refined image is shown, or it failed.
    pub fn finished(&self) -> bool {
        self.requested.is_some_and(|(id, preview)| {
            self.failed == Some(id) || (!preview && self.shown == Some((id, true)))
        })
    }

    /// A frame is on its way: the newest request has neither its image nor an error.
    pub fn waiting(&self) -> bool {
        self.requested.is_some_and(|(id, _)| {
            self.failed != Some(id) && self.shown.is_none_or(|(s, _)| s != id)
        })
    }
}

/// Texels per side of the painted normal disk.
pub const PAINT_SIZE: u32 = 64;

/// Paints `colour` into `t` with a round brush of `radius` at (x, y) on the normal disk
/// (x right, y up, in [-1, 1]); the brush's edge blends over one texel.
pub fn paint(t: &mut TransferImage, x: f32, y: f32, radius: f32, colour: [f32; 3]) {
    let (w, h) = (t.width as f32, t.height as f32);
    let (cx, cy) = ((x + 1.0) * 0.5 * w, (1.0 - y) * 0.5 * h);
    let r = (radius.max(0.0) * 0.5 * w).max(0.5);
    for j in 0..t.height {
        for i in 0..t.width {
            let d = ((i as f32 + 0.5 - cx).powi(2) + (j as f32 + 0.5 - cy).powi(2)).sqrt();
            let a = (r + 0.5 - d).clamp(0.0, 1.0);
            if a > 0.0 {
                let c = &mut t.colour[(j * t.width + i) as usize];
                for k in 0..3 {
                    c[k] += (colour[k] - c[k]) * a;
                }
            }
        }
    }
}

/// `script action 3 (screenshot)`: where in a script an error arose.
pub fn script_place(index: usize, action: &Action) -> String {
    let name = serde_json::to_value(action)
        .ok()
        .and_then(|v| v.get("action").and_then(|a| a.as_str()).map(str::to_owned))
        .unwrap_or_default();
    format!("script action {index} ({name})")
}

/// The style entry of species `name`, added when missing.
fn style_of<'a>(style: &'a mut PointStyle, name: &str) -> &'a mut SpeciesStyle {
    let i = match style.species.iter().position(|s| s.name == name) {
        Some(i) => i,
        None => {
            style.species.push(SpeciesStyle {
                name: name.to_string(),
                ..Default::default()
            });
            style.species.len() - 1
        }
    };
    &mut style.species[i]
}

/// A light direction turned by a drag on the light widget: dx about the view's vertical
/// axis, dy about its horizontal axis; it stays a unit vector.
pub fn drag_direction(direction: [f32; 3], dx: f32, dy: f32) -> [f32; 3] {
    let d = Vec3::from(direction).normalize_or(Vec3::Z);
    let yaw = mdlod_render::glam::Quat::from_rotation_y((dx * LIGHT_DEG_PER_PX).to_radians());
    let pitch = mdlod_render::glam::Quat::from_rotation_x((-dy * LIGHT_DEG_PER_PX).to_radians());
    (pitch * yaw * d).normalize().to_array()
}

/// Adapts the interactive screen error to hold the target frame time: coarser when the
/// last moving frame took longer than the target, finer when it took under half of it.
pub fn adapt_error(current_px: f32, last_frame_ms: f32, target_ms: f32, finest_px: f32) -> f32 {
    let finest = finest_px.max(0.25);
    if last_frame_ms > target_ms {
        (current_px.max(finest) * (last_frame_ms / target_ms).sqrt().clamp(1.25, 4.0)).min(256.0)
    } else if last_frame_ms < 0.5 * target_ms {
        (current_px / 1.25).max(finest)
    } else {
        current_px.max(finest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> ViewerState {
        let bounds = Bounds::new([0.0, 0.0, 0.0], [10.0, 10.0, 10.0]);
        let mut camera = Camera::default();
        camera.fit(&bounds, 4.0 / 3.0);
        ViewerState::new(
            vec![
                FrameInfo {
                    path: "a.mdlod".into(),
                    timestep: Some(0),
                },
                FrameInfo {
                    path: "b.mdlod".into(),
                    timestep: Some(100),
                },
                FrameInfo {
                    path: "c.mdlod".into(),
                    timestep: Some(200),
                },
            ],
            camera,
            bounds,
            [400, 300],
        )
    }

    #[test]
    fn scripts_refuse_what_render_refuses() {
        let mut s = state();
        s.attributes = vec!["c_pe".into(), "particles/mass".into()];
        let s = s;
        let refused = |a: Action, want: &str| {
            let e = s.check_script_action(3, &a).unwrap_err();
            assert!(e.starts_with("script action 3 ("), "{e}");
            assert!(e.contains(want), "{e} lacks {want}");
        };
        refused(
            Action::Light {
                index: 9,
                direction: [0.0, 0.0, 1.0],
            },
            "light index 9",
        );
        refused(
            Action::Attribute {
                name: Some("c_ke".into()),
            },
            "(attribute): no attribute \"c_ke\"; the data has c_pe, particles/mass",
        );
        for known in ["c_pe", "mass", "particles/mass"] {
            let a = Action::Attribute {
                name: Some(known.into()),
            };
            assert_eq!(s.check_script_action(1, &a), Ok(()), "{known}");
        }
        refused(
            Action::LightColour {
                index: 4,
                colour: [1.0; 3],
            },
            "(light_colour): light index 4",
        );
        refused(Action::RadiusScale { scale: 0.0 }, "radius scale 0");
        refused(Action::RadiusScale { scale: -1.0 }, "radius scale -1");
        refused(Action::Zoom { factor: 0.0 }, "zoom factor 0");
        refused(Action::Zoom { factor: -2.0 }, "zoom factor -2");
        refused(Action::Spp { n: 0 }, "0 samples");
        refused(Action::SndfIterations { n: 0 }, "0 S-NDF");
        refused(Action::ScreenError { px: -1.0 }, "screen error -1");
        assert!(s
            .check_script_action(0, &Action::ScreenError { px: 0.0 })
            .is_ok());
        refused(Action::Frame { index: 99 }, "frame 99");
        refused(Action::Frame { index: 3 }, "frame 3");
        let shot = |width, height| Action::Screenshot {
            path: "a.png".into(),
            width,
            height,
        };
        refused(shot(Some(0), Some(50)), "0x50");
        refused(
            shot(Some(64), None),
            "width 64 and height none: give both or neither",
        );
        refused(shot(None, Some(64)), "both or neither");
        refused(
            Action::Screenshot {
                path: "a.jpg".into(),
                width: None,
                height: None,
            },
            "a.jpg: screenshots are PNG images",
        );
        refused(Action::Pause { seconds: -1.0 }, "pause of -1 seconds");
        // Lights, colours, the BRDF, the explorer and the brush, as render and shade
        // refuse them.
        refused(
            Action::Light {
                index: 0,
                direction: [0.0; 3],
            },
            "(light): light direction [0.0, 0.0, 0.0] points nowhere",
        );
        refused(
            Action::AddLight {
                light: Light {
                    direction: [1.0, 0.0, 0.0],
                    colour: [2.0, -1.0, 0.0],
                },
            },
            "colour [2.0, -1.0, 0.0]: linear RGB",
        );
        refused(
            Action::SpeciesColour {
                name: "Cu".into(),
                colour: [0.5, 0.5, 1.5],
            },
            "(species_colour): colour",
        );
        refused(
            Action::Brdf {
                specular: -1.0,
                shininess: 20.0,
            },
            "specular -1",
        );
        refused(
            Action::Brdf {
                specular: 0.5,
                shininess: 0.0,
            },
            "shininess 0",
        );
        let explorer = |slices, disk_deg, tolerance_deg| Action::Explorer {
            slices,
            disk_deg,
            tolerance_deg,
        };
        refused(explorer(Some(0), None, None), "0 slices");
        refused(explorer(Some(6), Some(200.0), None), "disk of 200°");
        refused(explorer(Some(6), None, Some(-5.0)), "border of -5°");
        refused(
            Action::Paint {
                x: 5.0,
                y: 0.0,
                radius: 0.1,
                colour: [1.0; 3],
            },
            "paint at (5, 0)",
        );
        refused(
            Action::Paint {
                x: 0.0,
                y: 0.0,
                radius: -1.0,
                colour: [1.0; 3],
            },
            "radius -1",
        );
        refused(
            Action::TargetFrameMs { ms: 0.0 },
            "target frame time of 0 ms",
        );
        for ok in [
            shot(None, None),
            shot(Some(64), Some(48)),
            Action::Frame { index: 2 },
            Action::Zoom { factor: 0.5 },
            Action::Spp { n: 1 },
            Action::Light {
                index: 0,
                direction: [0.0, 0.0, 1.0],
            },
            explorer(Some(6), Some(90.0), Some(0.0)),
            explorer(None, None, None),
            Action::Brdf {
                specular: 0.0,
                shininess: 1.0,
            },
        ] {
            assert_eq!(s.check_script_action(0, &ok), Ok(()), "{ok:?}");
        }
        // Colouring by an attribute the data does not keep.
        let plain = state();
        let e = plain
            .check_script_action(
                1,
                &Action::ColourMap {
                    map: Some(ColourMap::Viridis),
                },
            )
            .unwrap_err();
        assert!(e.contains("keeps no attribute to colour by"), "{e}");
    }

    #[test]
    fn scripts_refuse_a_species_the_one_frame_lacks() {
        let mut s = state();
        s.species = vec![("Cu".into(), [1.0, 0.5, 0.2]), ("Ag".into(), [0.8; 3])];
        let colour = |name: &str| Action::SpeciesColour {
            name: name.into(),
            colour: [0.0, 1.0, 0.0],
        };
        // A trajectory's later frames may bring it: allowed.
        assert_eq!(s.check_script_action(0, &colour("Au")), Ok(()));
        s.frames.truncate(1);
        let e = s.check_script_action(2, &colour("Au")).unwrap_err();
        assert_eq!(
            e,
            "script action 2 (species_colour): no species \"Au\"; the data has Cu, Ag"
        );
        let hide = Action::SpeciesVisible {
            name: "1".into(),
            visible: false,
        };
        assert!(s
            .check_script_action(0, &hide)
            .unwrap_err()
            .contains("(species_visible): no species \"1\""));
        assert_eq!(s.check_script_action(0, &colour("Ag")), Ok(()));
    }

    /// A perspective fit's target lies off the data's centre; switched to orthographic
    /// before any pan, the view is fitted again (centred) at the same zoom; after a pan,
    /// the user's target stays.
    #[test]
    fn a_projection_switch_before_any_pan_fits_the_new_projection() {
        let mut s = state();
        s.apply(&Action::Fit);
        let perspective = s.camera.clone();
        s.apply(&Action::Zoom { factor: 2.0 });
        s.apply(&Action::Projection { orthographic: true });
        let mut want = perspective.clone();
        want.projection = Projection::Orthographic;
        want.fit(&s.bounds, s.aspect());
        assert_eq!(s.camera.target, want.target);
        assert!((s.camera.distance - want.distance / 2.0).abs() < 1e-3 * want.distance);
        // And back: the perspective fit at the same zoom.
        s.apply(&Action::Projection {
            orthographic: false,
        });
        assert_eq!(s.camera.target, perspective.target);
        assert!(
            (s.camera.distance - perspective.distance / 2.0).abs() < 1e-3 * perspective.distance
        );
        s.apply(&Action::Pan { dx: 30.0, dy: 0.0 });
        let panned = s.camera.target;
        s.apply(&Action::Projection { orthographic: true });
        assert_eq!(s.camera.target, panned);
        assert_eq!(s.camera.projection, Projection::Orthographic);
    }

    #[test]
    fn camera_actions_move_the_camera_and_fit_restores_it() {
        let mut s = state();
        let fitted = s.camera.clone();
        let c = s.apply(&Action::Orbit { dx: 50.0, dy: 0.0 });
        assert!(c.scene && !c.lighting);
        assert!((s.camera.azimuth_deg - (fitted.azimuth_deg - 15.0)).abs() < 1e-4);
        s.apply(&Action::Orbit { dx: 0.0, dy: 50.0 });
        assert!((s.camera.elevation_deg - (fitted.elevation_deg + 15.0)).abs() < 1e-4);
        s.apply(&Action::Zoom { factor: 2.0 });
        assert!((s.camera.distance - fitted.distance / 2.0).abs() < 1e-3);
        let target = s.camera.target;
        s.apply(&Action::Pan { dx: 40.0, dy: 0.0 });
        assert!((s.camera.target - target).length() > 0.0);
        // A bad zoom changes nothing.
        assert_eq!(s.apply(&Action::Zoom { factor: -1.0 }), Changed::default());
        // A fit keeps the direction: turned back, it restores the first view.
        s.apply(&Action::Fit);
        s.apply(&Action::Orbit {
            dx: -50.0,
            dy: -50.0,
        });
        s.apply(&Action::Fit);
        assert!((s.camera.target - fitted.target).length() < 1e-4);
        assert!((s.camera.distance - fitted.distance).abs() < 1e-3);
    }

    #[test]
    fn lighting_actions_change_only_the_lighting() {
        let mut s = state();
        let c = s.apply(&Action::Light {
            index: 0,
            direction: [0.0, 0.0, 2.0],
        });
        assert_eq!(
            c,
            Changed {
                scene: false,
                lighting: true
            }
        );
        assert_eq!(s.settings.lights[0].direction, [0.0, 0.0, 1.0]);
        s.apply(&Action::DragLight {
            index: 0,
            dx: 180.0,
            dy: 0.0,
        });
        let d = Vec3::from(s.settings.lights[0].direction);
        assert!((d.length() - 1.0).abs() < 1e-5);
        assert!((d.x - 1.0).abs() < 1e-4, "90 degrees to the right: {d}");
        s.apply(&Action::AddLight {
            light: Light {
                direction: [1.0, 0.0, 0.0],
                colour: [0.2, 0.3, 1.0],
            },
        });
        assert_eq!(s.settings.shade_lights().lights.len(), 2);
        assert_eq!(
            s.apply(&Action::RemoveLight { index: 5 }),
            Changed::default()
        );
        s.apply(&Action::RemoveLight { index: 0 });
        assert_eq!(s.settings.lights.len(), 1);
        s.apply(&Action::Brdf {
            specular: 0.0,
            shininess: 8.0,
        });
        assert_eq!(s.settings.sphere_lighting().specular, 0.0);
        assert_eq!(
            s.settings.sphere_lighting().direction_view,
            Vec3::new(1.0, 0.0, 0.0)
        );
        // With no light left, the spheres take the ambient alone, as the S-NDFs do.
        s.apply(&Action::RemoveLight { index: 0 });
        assert!(s.settings.shade_lights().lights.is_empty());
        assert_eq!(s.settings.sphere_lighting().colour, [0.0; 3]);
    }

    #[test]
    fn style_actions_reach_the_render_options() {
        let mut s = state();
        assert!(
            s.apply(&Action::SpeciesVisible {
                name: "Ag".into(),
                visible: false
            })
            .scene
        );
        s.apply(&Action::SpeciesColour {
            name: "Ag".into(),
            colour: [2.0, 0.5, 0.0],
        });
        s.apply(&Action::RadiusScale { scale: 0.5 });
        assert_eq!(
            s.apply(&Action::RadiusScale { scale: 0.0 }),
            Changed::default()
        );
        s.apply(&Action::ColourMap {
            map: Some(ColourMap::Magma),
        });
        let o = s.render_options([10, 10]);
        assert_eq!(o.style.species.len(), 1);
        assert_eq!(o.style.species[0].colour, Some([1.0, 0.5, 0.0]));
        assert!(o.style.species[0].hidden);
        assert_eq!(o.style.radius_scale, 0.5);
        assert_eq!(o.style.colour_map, Some(ColourMap::Magma));
    }

    #[test]
    fn painting_the_normal_disk_makes_a_transfer_function() {
        let mut s = state();
        assert!(s.settings.shade_lights().transfer.is_none());
        let c = s.apply(&Action::Paint {
            x: 0.5,
            y: 0.5,
            radius: 0.2,
            colour: [1.0, 0.0, 0.0],
        });
        assert_eq!(
            c,
            Changed {
                scene: false,
                lighting: true
            }
        );
        let t = s.settings.shade_lights().transfer.unwrap();
        // The brush's centre is red, the opposite side of the disk untouched.
        let n = |x: f32, y: f32| mdlod_render::glam::Vec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        assert_eq!(t.colour(n(0.5, 0.5)), [1.0, 0.0, 0.0]);
        assert_eq!(t.colour(n(-0.5, -0.5)), [0.5; 3]);
        assert!(s.apply(&Action::ClearPaint).lighting);
        assert!(s.settings.shade_lights().transfer.is_none());
        s.apply(&Action::Explorer {
            slices: Some(4),
            disk_deg: Some(30.0),
            tolerance_deg: Some(500.0),
        });
        let e = s.settings.shade_lights().explorer.unwrap();
        assert_eq!((e.slices, e.disk_deg, e.tolerance_deg), (4, 30.0, 45.0));
    }

    #[test]
    fn timesteps_step_and_wrap() {
        let mut s = state();
        assert!(s.apply(&Action::Step { delta: 1 }).scene);
        assert_eq!(s.frame, 1);
        s.apply(&Action::Step { delta: -2 });
        assert_eq!(s.frame, 2);
        assert_eq!(s.apply(&Action::Frame { index: 7 }), Changed::default());
        assert_eq!(s.frame, 2);
    }

    #[test]
    fn options_follow_the_mode() {
        let mut s = state();
        s.apply(&Action::Mode {
            mode: Mode::Supersampled,
        });
        assert_eq!(s.render_options([10, 10]).spp, 8);
        assert_eq!(s.interactive_options([10, 10], 4.0).spp, 1);
        // At 4 px the preview is drawn at half size with the same cut: 2 of its pixels.
        let o = s.interactive_options([10, 10], 4.0);
        assert_eq!((o.width, o.height, o.error_px), (5, 5, 2.0));
        let o = s.interactive_options([101, 60], 2.0);
        assert_eq!((o.width, o.height, o.error_px), (101, 60, 2.0));
        let o = s.interactive_options([101, 60], 12.0);
        assert_eq!((o.width, o.height, o.error_px), (26, 15, 3.0));
        s.apply(&Action::Mode { mode: Mode::Sndf });
        assert!(matches!(
            s.render_options([10, 10]).mode,
            RenderMode::Sndf { iterations: 64, .. }
        ));
        assert_eq!(
            s.interactive_options([10, 10], 1.0).mode,
            RenderMode::Spheres
        );
        s.apply(&Action::Mode { mode: Mode::Iso });
        match s.render_options([10, 10]).mode {
            RenderMode::Density(d) => assert_eq!((d.iso, d.colour_map), (Some(0.3), None)),
            m => panic!("{m:?}"),
        }
        // Coloured by the attribute: the iso-surface too.
        s.apply(&Action::ColourMap {
            map: Some(ColourMap::Magma),
        });
        match s.render_options([10, 10]).mode {
            RenderMode::Density(d) => assert_eq!(d.colour_map, Some(ColourMap::Magma)),
            m => panic!("{m:?}"),
        }
    }

    #[test]
    fn the_interactive_error_holds_the_target_frame_time() {
        // Too slow: coarser, by more when much slower; bounded.
        assert!(adapt_error(1.0, 66.0, 33.0, 1.0) > 1.0);
        assert!(adapt_error(1.0, 330.0, 33.0, 1.0) > adapt_error(1.0, 66.0, 33.0, 1.0));
        assert!(adapt_error(200.0, 1e6, 33.0, 1.0) <= 256.0);
        // Fast: finer, never below the refined error.
        assert!(adapt_error(8.0, 5.0, 33.0, 1.0) < 8.0);
        assert_eq!(adapt_error(1.0, 5.0, 33.0, 1.0), 1.0);
        // Within the band: unchanged.
        assert_eq!(adapt_error(4.0, 20.0, 33.0, 1.0), 4.0);
    }

    #[test]
    fn the_sphere_modes_take_the_first_lights_colour_and_densities_a_black_background() {
        let mut s = state();
        s.apply(&Action::LightColour {
            index: 0,
            colour: [0.0, 0.0, 1.0],
        });
        let o = s.render_options([64, 48]);
        assert_eq!(o.lighting.colour, [0.0, 0.0, 1.0]);
        assert_eq!(o.background, [1.0; 3]);
        s.apply(&Action::Mode {
            mode: Mode::Density,
        });
        assert_eq!(s.render_options([64, 48]).background, [0.0; 3]);
    }

    #[test]
    fn zoom_keeps_the_camera_within_reach_of_the_data() {
        let mut s = state();
        let r = s.bounds.radius();
        // Holding `-`: the distance stops growing, and `+` brings it back.
        for _ in 0..2000 {
            s.apply(&Action::Zoom { factor: 0.8 });
        }
        assert!(s.camera.distance.is_finite());
        assert!((s.camera.distance - ZOOM_RANGE.1 * r).abs() <= 1e-3 * ZOOM_RANGE.1 * r);
        s.camera.check().unwrap();
        assert_eq!(s.apply(&Action::Zoom { factor: 0.8 }), Changed::default());
        let far = s.camera.distance;
        assert!(s.apply(&Action::Zoom { factor: 1.25 }).scene);
        assert!((s.camera.distance - far / 1.25).abs() <= 1e-3 * far);
        // Holding `+`: it stops well above the denormals.
        for _ in 0..5000 {
            s.apply(&Action::Zoom { factor: 1.25 });
        }
        assert!((s.camera.distance - ZOOM_RANGE.0 * r).abs() <= 1e-3 * ZOOM_RANGE.0 * r);
        assert!(s.camera.distance.is_normal());
        s.camera.check().unwrap();
    }

    #[test]
    fn a_light_colour_changes_in_place() {
        let mut s = state();
        s.apply(&Action::AddLight {
            light: Light {
                direction: [1.0, 0.0, 0.0],
                colour: [0.2, 0.3, 1.0],
            },
        });
        let first = s.settings.lights[0].direction;
        let c = s.apply(&Action::LightColour {
            index: 0,
            colour: [1.0, 0.5, 0.0],
        });
        assert_eq!(
            c,
            Changed {
                scene: false,
                lighting: true
            }
        );
        // The first light is still first: the sphere modes still light from it.
        assert_eq!(s.settings.lights.len(), 2);
        assert_eq!(s.settings.lights[0].direction, first);
        assert_eq!(s.settings.lights[0].colour, [1.0, 0.5, 0.0]);
        assert_eq!(s.settings.lights[1].colour, [0.2, 0.3, 1.0]);
        assert_eq!(
            s.settings.sphere_lighting().direction_view,
            Vec3::from(first).normalize()
        );
        assert_eq!(
            s.apply(&Action::LightColour {
                index: 2,
                colour: [1.0; 3]
            }),
            Changed::default()
        );
    }

    #[test]
    fn fitting_uses_the_shown_frames_bounds() {
        let mut s = state();
        let first = s.bounds;
        let second = Bounds::new([100.0, 0.0, 0.0], [140.0, 40.0, 40.0]);
        // The render thread reports frame 1's bounds (here before it is shown).
        s.set_frame_bounds(Path::new("b.mdlod"), second, vec![]);
        assert_eq!(s.bounds, first);
        s.apply(&Action::Step { delta: 1 });
        assert_eq!(s.bounds, second);
        s.apply(&Action::Fit);
        assert_eq!(s.camera, fitted(&s, &second));
        // Frame 2 is not known yet: the last bounds stand in until it is reported.
        s.apply(&Action::Step { delta: 1 });
        assert_eq!(s.bounds, second);
        let third = Bounds::new([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        s.set_frame_bounds(Path::new("c.mdlod"), third, vec![]);
        assert_eq!(s.bounds, third);
        s.apply(&Action::Frame { index: 0 });
        assert_eq!(s.bounds, first);
        s.apply(&Action::Fit);
        assert_eq!(s.camera, fitted(&s, &first));
    }

    /// The camera `mdlod render` fits to `bounds` from the viewer's direction.
    fn fitted(s: &ViewerState, bounds: &Bounds) -> Camera {
        let mut c = s.camera.clone();
        c.fit(bounds, s.aspect());
        c
    }

    #[test]
    fn a_single_frame_does_not_play() {
        let mut s = state();
        assert!(s.can_play());
        s.frames.truncate(1);
        assert!(!s.can_play());
    }

    #[test]
    fn coarse_previews_are_drawn_smaller_and_settle_at_one_size() {
        assert_eq!(
            [1.0, 3.9, 4.0, 7.9, 8.0, 256.0].map(preview_divisor),
            [1, 1, 2, 2, 4, 4]
        );
        // Perspective S-NDF views preview spheres, drawn smaller like any sphere preview.
        let mut s = state();
        s.apply(&Action::Mode { mode: Mode::Sndf });
        let o = s.interactive_options([40, 20], 16.0);
        assert_eq!((o.width, o.height, o.error_px), (10, 5, 4.0));
        assert_eq!(o.mode, RenderMode::Spheres);
        // A frame at half size with room to spare, but not for four times the pixels,
        // keeps the half size; with room for them it goes on to the full size.
        assert_eq!(adapt_preview_error(4.0, 12.0, 33.0, 1.0, 2), 4.0);
        assert!(adapt_preview_error(4.0, 5.0, 33.0, 1.0, 2) < 4.0);
        assert_eq!(adapt_preview_error(8.0, 10.0, 33.0, 1.0, 4), 8.0);
        assert!(adapt_preview_error(8.0, 1.0, 33.0, 1.0, 4) < 8.0);
        // Full size, too slow: coarser at once, whatever the divisor it reaches.
        assert!(adapt_preview_error(3.5, 100.0, 33.0, 1.0, 1) >= 4.0);
        // A viewer whose full-size previews are too slow and quarter-size ones fast
        // settles rather than switching sizes each frame: a cost model of a fixed part
        // plus one per pixel, 40 ms at full size.
        let cost = |e: f32| 4.0 + 36.0 / (preview_divisor(e) as f32).powi(2) + 8.0 / e;
        let mut e = 1.0;
        let mut divisors = vec![];
        for _ in 0..40 {
            e = adapt_preview_error(e, cost(e), 33.0, 1.0, preview_divisor(e));
            divisors.push(preview_divisor(e));
        }
        assert!(
            divisors[20..].windows(2).all(|w| w[0] == w[1]),
            "{divisors:?}"
        );
        assert!(cost(e) <= 33.0, "{e}: {} ms", cost(e));
    }

    #[test]
    fn orbiting_orthographic_sndf_previews_use_the_adapted_error() {
        let mut s = state();
        s.apply(&Action::Mode { mode: Mode::Sndf });
        s.apply(&Action::Projection { orthographic: true });
        // The S-MIP keeps the settled error; its sphere fallback takes the preview's.
        let o = s.interactive_options([10, 10], 6.0);
        assert!(matches!(o.mode, RenderMode::Sndf { .. }));
        // The S-MIP's tiles are sampled at the window's size: no smaller preview.
        assert_eq!((o.width, o.height, o.error_px), (10, 10, 1.0));
        assert_eq!(s.sphere_preview_error(6.0), 6.0);
        assert_eq!(s.sphere_preview_error(0.5), 1.0);
        // Slow S-MIP previews stop adapting where the S-MIP stops coarsening.
        let mut e = 1.0;
        for _ in 0..50 {
            e = adapt_error(e, 500.0, 33.0, 1.0).min(smip_preview_cap(1.0));
        }
        assert_eq!(e, 8.0);
        assert_eq!(crate::app::coarsen_levels(e, 1.0), SMIP_MAX_COARSEN);
    }

    #[test]
    fn stale_images_are_dropped_and_the_newest_request_settles() {
        let mut r = Requests::default();
        let sndf = r.send(false);
        assert!(r.image(sndf, false));
        let preview = r.send(true);
        // An image of an overtaken request still shows until the newer one answers.
        assert!(r.image(sndf, false));
        assert!(r.waiting());
        assert!(r.image(preview, false));
        let standard = r.send(false);
        assert!(r.image(standard, true));
        assert!(r.finished() && !r.waiting());
        // Batches of the old S-NDF view arriving late do not replace the new image.
        assert!(!r.image(sndf, false));
        assert!(!r.image(preview, false));
        assert!(r.finished());
    }

    #[test]
    fn an_error_ends_the_request_and_its_message_clears_when_the_view_recovers() {
        let mut r = Requests::default();
        let a = r.send(false);
        assert!(r.image(a, true));
        let b = r.send(false);
        assert!(r.waiting() && !r.finished());
        // An error of the newest request: it is done (playback stops, no frame queued).
        assert!(r.error(b, "frame-1.mdlod: missing".into()));
        assert!(r.finished() && !r.waiting());
        assert_eq!(r.message(), Some("frame-1.mdlod: missing"));
        // Images of older requests are stale now.
        assert!(!r.image(a, true));
        // An error of an overtaken request does not end the newest one.
        let c = r.send(false);
        assert!(!r.error(b, "late".into()));
        assert!(!r.finished() && r.waiting());
        assert!(r.image(c, true));
        assert!(r.finished());
        assert_eq!(r.message(), None);
        // A note stays until an image of a later request.
        r.note("wrote a.png".into());
        assert!(r.image(c, true));
        assert_eq!(r.message(), Some("wrote a.png"));
        let d = r.send(false);
        assert!(r.image(d, true));
        assert_eq!(r.message(), None);
    }

    #[test]
    fn script_errors_name_the_action_and_its_line() {
        let script = "[\n  {\"action\": \"orbit\", \"dx\": 1, \"dy\": 0},\n  {\"action\": \"screenshot\",\n   \"width\": 64, \"height\": 48}\n]";
        assert_eq!(
            parse_script(script).unwrap_err(),
            "action 1 (screenshot, line 3): missing field `path`"
        );
        let e = parse_script("[{\"action\": \"zoom\", \"factr\": 2}]").unwrap_err();
        assert!(
            e.starts_with("action 0 (zoom, line 1): unknown field `factr`"),
            "{e}"
        );
        // A light's own fields are checked too (`color` for `colour` was a white light).
        let e = parse_script(
            "[{\"action\": \"add_light\", \"light\": {\"direction\": [0, 0, 1], \"color\": [1, 0, 0]}}]",
        )
        .unwrap_err();
        assert!(e.contains("unknown field `color`"), "{e}");
        let e = parse_script("[{\"action\": \"fly\"}]").unwrap_err();
        assert!(
            e.starts_with("action 0 (fly, line 1): unknown variant `fly`"),
            "{e}"
        );
        // Not JSON at all: serde's own place.
        assert!(parse_script("[{").unwrap_err().contains("line 1"));
        assert!(parse_script("{}")
            .unwrap_err()
            .contains("a list of actions"));
        assert_eq!(parse_script("[]").unwrap(), vec![]);
    }

    #[test]
    fn scripts_parse_and_unknown_actions_are_refused() {
        let script = r#"[{"action": "orbit", "dx": 120, "dy": 0},
            {"action": "mode", "mode": "sndf"},
            {"action": "screenshot", "path": "a.png"},
            {"action": "light", "index": 0, "direction": [1, 1, 1]},
            {"action": "step", "delta": 1}, {"action": "wait_still"}]"#;
        let actions: Vec<Action> = serde_json::from_str(script).unwrap();
        assert_eq!(actions.len(), 6);
        assert_eq!(
            actions[2],
            Action::Screenshot {
                path: "a.png".into(),
                width: None,
                height: None
            }
        );
        assert!(serde_json::from_str::<Vec<Action>>(r#"[{"action": "fly"}]"#).is_err());
        // `render`'s name of the standard mode.
        assert_eq!(
            serde_json::from_str::<Action>(r#"{"action": "mode", "mode": "spheres"}"#).unwrap(),
            Action::Mode {
                mode: Mode::Standard
            }
        );
        assert!(
            serde_json::from_str::<Vec<Action>>(r#"[{"action": "zoom", "factr": 2}]"#).is_err()
        );
    }
}
