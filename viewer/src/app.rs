//! The window: eframe (winit + egui-winit + egui-wgpu) around the render thread.
//!
//! Each repaint drains the render thread's replies, draws the panel and the latest image,
//! turns mouse and keys into [`Action`]s, runs the next step of a script, and sends one
//! render request when the state changed. While the user drags, requests are quick
//! previews whose screen error adapts to hold the target frame time; 150 ms after the
//! last input the refined request follows (supersampling, progressive S-NDFs).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eframe::egui;
use mdlod_render::{RgbaImage, ViewFile};

use crate::state::{
    adapt_error, adapt_preview_error, smip_preview_cap, Action, Changed, Mode, Requests,
    ViewerState, SMIP_MAX_COARSEN,
};
use crate::worker::{FrameStats, Reply, Request, Worker};

/// Width of the control panel left of the image (logical pixels).
pub(crate) const PANEL_WIDTH: f32 = 270.0;

/// How long a closing window waits for the render thread to end.
const EXIT_WAIT: Duration = Duration::from_secs(2);

/// Input this recent makes a frame a quick preview.
const MOVING: Duration = Duration::from_millis(150);

/// The latest image from the render thread.
struct Shown {
    image: RgbaImage,
    stats: FrameStats,
    interactive: bool,
    refined: bool,
}

/// A script being played: the actions left and what the current one waits for.
pub(crate) struct Script {
    pub actions: VecDeque<Action>,
    /// The next action's index in the script (for error messages).
    next: usize,
    /// The action being played (`script action 3 (screenshot)`), which an error names.
    current: Option<String>,
    waiting: Option<Wait>,
    deadline: Instant,
}

impl Script {
    pub fn new(actions: Vec<Action>, timeout: Duration) -> Script {
        Script {
            actions: actions.into(),
            next: 0,
            current: None,
            waiting: None,
            deadline: Instant::now()
                .checked_add(timeout)
                .unwrap_or_else(|| Instant::now() + Duration::from_secs(u64::from(u32::MAX))),
        }
    }
}

enum Wait {
    /// Until the view is refined, then run this action.
    Refined(Action),
    /// Until the render thread has written this many files.
    Writes,
    /// Until this moment.
    Until(Instant),
}

pub(crate) struct ViewerApp {
    pub state: ViewerState,
    worker: Worker,
    texture: Option<egui::TextureHandle>,
    shown: Option<Shown>,
    /// The requests sent, the image shown and the status message.
    requests: Requests,
    /// The timestep changed: prefetch the next one after the render request.
    prefetch: bool,
    /// The render thread is gone (it panicked): nothing more will come.
    worker_gone: bool,
    dirty: Changed,
    last_input: Option<Instant>,
    /// Screen error of previews, adapted to the target frame time.
    moving_error: f32,
    script: Option<Script>,
    /// Files the render thread has yet to write.
    pending_writes: usize,
    /// The first error, for the exit status when a script runs.
    pub outcome: Arc<Mutex<Option<String>>>,
    playing: bool,
    last_step: Instant,
    light_index: usize,
    brush_colour: [f32; 3],
    brush_radius: f32,
    environment_path: String,
}

impl ViewerApp {
    pub fn new(
        state: ViewerState,
        worker: Worker,
        script: Option<Script>,
        outcome: Arc<Mutex<Option<String>>>,
    ) -> ViewerApp {
        let moving_error = state.settings.error_px.max(1.0);
        ViewerApp {
            state,
            worker,
            texture: None,
            shown: None,
            requests: Requests::default(),
            prefetch: false,
            worker_gone: false,
            dirty: Changed {
                scene: true,
                lighting: false,
            },
            last_input: None,
            moving_error,
            script,
            pending_writes: 0,
            outcome,
            playing: false,
            last_step: Instant::now(),
            light_index: 0,
            brush_colour: [0.9, 0.2, 0.1],
            brush_radius: 0.15,
            environment_path: String::new(),
        }
    }

    fn fail(&mut self, message: String) {
        self.requests.note(message.clone());
        self.script_failed(message);
    }

    /// The first error of a script fails it, named by the action being played (a view
    /// file that cannot be read, a screenshot's directory missing).
    fn script_failed(&mut self, message: String) {
        if let Some(script) = &self.script {
            let message = match &script.current {
                Some(place) if !message.starts_with("script action ") => {
                    format!("{place}: {message}")
                }
                _ => message,
            };
            let mut o = self.outcome.lock().unwrap_or_else(|e| e.into_inner());
            o.get_or_insert(message);
        }
    }

    /// Applies an action from the mouse, keys or panel (`user`) or a script.
    fn act(&mut self, action: Action, user: bool) {
        match &action {
            Action::SaveView { path } => {
                let [w, h] = self.state.size;
                if let Err(e) = ViewFile::from_camera(&self.state.camera)
                    .seen_in(w, h)
                    .save(path)
                {
                    self.fail(e.to_string());
                }
                return;
            }
            Action::Environment { path } => {
                match path {
                    None => self.state.settings.environment = None,
                    Some(p) => match RgbaImage::load_png(p) {
                        Ok(image) => {
                            self.state.settings.environment = Some(Arc::new(
                                mdlod_render::sndf::EnvironmentMap::from_image(&image),
                            ))
                        }
                        Err(e) => return self.fail(e.to_string()),
                    },
                }
                self.dirty.lighting = true;
                return;
            }
            Action::LoadView { path } => {
                match ViewFile::load(path) {
                    Ok(v) => {
                        let c = v.to_camera(&self.state.bounds, self.state.aspect());
                        self.state.set_camera(c);
                        self.dirty.scene = true;
                    }
                    Err(e) => self.fail(e.to_string()),
                }
                return;
            }
            _ => {}
        }
        let before = (self.state.frame, self.state.settings.mode);
        let c = self.state.apply(&action);
        self.dirty.scene |= c.scene;
        self.dirty.lighting |= c.lighting;
        if user && c.scene {
            self.last_input = Some(Instant::now());
        }
        if self.state.frame != before.0 {
            // After the render request (see `send_render`): the frame shown comes first.
            self.prefetch = true;
        }
        if self.state.settings.mode != before.1 {
            // Another mode costs another time: its previews adapt from the settled error.
            self.moving_error = self.state.settings.error_px.max(1.0);
        }
    }

    fn prefetch_next(&self) {
        let n = self.state.frames.len();
        if n > 1 {
            let next = &self.state.frames[(self.state.frame + 1) % n].path;
            self.worker.send(Request::Prefetch(next.clone()));
        }
    }

    fn moving(&self) -> bool {
        self.last_input.is_some_and(|t| t.elapsed() < MOVING)
    }

    /// The view shows the current state, as refined as the mode goes (or its request
    /// failed: the view gets no further).
    fn settled(&self) -> bool {
        !self.dirty.scene && !self.dirty.lighting && self.requests.finished()
    }

    /// A preview was the last request.
    fn previewing(&self) -> bool {
        self.requests.requested().is_some_and(|(_, p)| p)
    }

    fn send_render(&mut self) {
        let interactive = self.moving() && self.dirty.scene;
        let size = self.state.size;
        let opts = if interactive {
            self.state.interactive_options(size, self.moving_error)
        } else {
            self.state.render_options(size)
        };
        let id = self.requests.send(interactive);
        self.worker.send(Request::Render {
            id,
            path: self.state.frames[self.state.frame].path.clone(),
            opts,
            shade: self.state.settings.shade_lights(),
            interactive,
            coarsen: if interactive {
                coarsen_levels(self.moving_error, self.state.settings.error_px)
            } else {
                0
            },
            sphere_error_px: if interactive {
                self.state.sphere_preview_error(self.moving_error)
            } else {
                self.state.settings.error_px
            },
        });
        self.dirty = Changed::default();
        if std::mem::take(&mut self.prefetch) {
            self.prefetch_next();
        }
    }

    fn receive(&mut self, ctx: &egui::Context) {
        let (replies, disconnected) = drain(&self.worker.rx);
        for reply in replies {
            match reply {
                Reply::Image {
                    id,
                    image,
                    stats,
                    interactive,
                    refined,
                } => {
                    // Images of requests overtaken by newer ones are still shown (they
                    // are the nearest thing to the view), but do not settle it; those
                    // older than one answered are stale.
                    if !self.requests.image(id, refined) {
                        continue;
                    }
                    // How many times smaller than the window the image was drawn (a
                    // coarse preview's; see `interactive_options`).
                    let divisor = drawn_smaller(self.state.size, &image);
                    if interactive {
                        let finest = self.state.settings.error_px.max(1.0);
                        let target = self.state.settings.target_frame_ms;
                        // S-MIP previews (they have bins) coarsen by a few levels at most.
                        self.moving_error = if stats.bins.is_some() {
                            adapt_error(self.moving_error, stats.frame_ms, target, finest)
                                .min(smip_preview_cap(finest))
                        } else {
                            adapt_preview_error(
                                self.moving_error,
                                stats.frame_ms,
                                target,
                                finest,
                                divisor,
                            )
                        };
                    }
                    let colour = egui::ColorImage::from_rgba_unmultiplied(
                        [image.width as usize, image.height as usize],
                        &image.data,
                    );
                    // A smaller preview is stretched smoothly; the window's own size is
                    // shown pixel for pixel.
                    let filter = if divisor > 1 {
                        egui::TextureOptions::LINEAR
                    } else {
                        egui::TextureOptions::NEAREST
                    };
                    match &mut self.texture {
                        Some(t) => t.set(colour, filter),
                        None => self.texture = Some(ctx.load_texture("view", colour, filter)),
                    }
                    self.shown = Some(Shown {
                        image,
                        stats,
                        interactive,
                        refined,
                    });
                }
                Reply::Bounds {
                    path,
                    bounds,
                    boxes,
                } => self.state.set_frame_bounds(&path, bounds, boxes),
                Reply::Written { out, result } => {
                    self.pending_writes = self.pending_writes.saturating_sub(1);
                    match result {
                        Ok(()) => self.requests.note(format!("wrote {}", out.display())),
                        Err(e) => self.fail(e),
                    }
                }
                Reply::Error { id, message } => {
                    if self.requests.error(id, message.clone()) {
                        // The view gets no further: playback stops at the bad frame.
                        self.playing = false;
                    }
                    self.script_failed(message);
                }
            }
        }
        if disconnected && !self.worker_gone {
            self.worker_gone = true;
            self.playing = false;
            self.fail("the render thread stopped".into());
        }
    }

    /// Runs the script's next step; returns true while it has work left.
    fn step_script(&mut self, ctx: &egui::Context) -> bool {
        if self.script.is_some()
            && self
                .outcome
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .is_some()
        {
            // The first error ends the script (the command then fails with it).
            self.script = None;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return false;
        }
        let Some(script) = self.script.as_mut() else {
            return false;
        };
        if Instant::now() > script.deadline {
            let left = script.actions.len();
            // While the script is still set: the timeout fails the command.
            let what = format!(
                "the script ran past its --script-timeout here ({left} actions after it not \
                 played)"
            );
            let message = match &script.current {
                Some(place) => format!("{place}: {what}"),
                None => what,
            };
            self.fail(message);
            // Exit now, not once the frame in progress is done.
            self.worker.abandon();
            self.script = None;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return false;
        }
        let waiting = script.waiting.take();
        match waiting {
            Some(Wait::Writes) => {
                if self.pending_writes > 0 {
                    self.wait(Wait::Writes);
                }
                return true;
            }
            Some(Wait::Until(t)) => {
                if Instant::now() < t {
                    self.wait(Wait::Until(t));
                }
                return true;
            }
            Some(Wait::Refined(action)) => {
                if self.settled() {
                    self.run_when_refined(action);
                } else {
                    self.wait(Wait::Refined(action));
                }
                return true;
            }
            None => {}
        }
        let Some(script) = self.script.as_mut() else {
            return false;
        };
        let Some(action) = script.actions.pop_front() else {
            self.script = None;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return false;
        };
        let index = script.next;
        script.next += 1;
        script.current = Some(crate::state::script_place(index, &action));
        // Values `mdlod render` refuses fail the script (the panel's widgets clamp).
        if let Err(e) = self.state.check_script_action(index, &action) {
            self.fail(e);
            return true;
        }
        match action {
            Action::Screenshot {
                path,
                width: Some(w),
                height: Some(h),
            } => {
                let opts = self.state.render_options([w, h]);
                self.worker.send(Request::Screenshot {
                    path: self.state.frames[self.state.frame].path.clone(),
                    opts,
                    shade: self.state.settings.shade_lights(),
                    out: path,
                });
                self.pending_writes += 1;
                script.waiting = Some(Wait::Writes);
            }
            Action::Screenshot { .. } | Action::SaveSndf { .. } | Action::WaitStill => {
                script.waiting = Some(Wait::Refined(action));
            }
            Action::Quit => {
                script.actions.clear();
            }
            Action::Pause { seconds } => {
                let d = Duration::from_secs_f32(seconds.clamp(0.0, 3600.0));
                script.waiting = Some(Wait::Until(Instant::now() + d));
            }
            // Camera moves count as the user's: previews first, then the refined view.
            other => self.act(other, true),
        }
        true
    }

    fn wait(&mut self, w: Wait) {
        if let Some(s) = self.script.as_mut() {
            s.waiting = Some(w);
        }
    }

    /// A script action that needed the refined view.
    fn run_when_refined(&mut self, action: Action) {
        match action {
            Action::Screenshot { path, .. } => {
                let saved = match &self.shown {
                    Some(s) => s.image.save_png(&path).map_err(|e| e.to_string()),
                    None => Err("nothing shown yet".into()),
                };
                if let Err(e) = saved {
                    self.fail(e);
                }
            }
            Action::SaveSndf { path } => {
                self.worker.send(Request::SaveSndf { out: path });
                self.pending_writes += 1;
                if let Some(s) = self.script.as_mut() {
                    s.waiting = Some(Wait::Writes);
                }
            }
            _ => {}
        }
    }

    fn keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let mut actions = vec![];
        ctx.input(|i| {
            use egui::Key;
            let step = if i.modifiers.shift { 15.0 } else { 5.0 };
            let px = step / crate::state::ORBIT_DEG_PER_PX;
            for (key, a) in [
                (Key::ArrowLeft, Action::Orbit { dx: -px, dy: 0.0 }),
                (Key::ArrowRight, Action::Orbit { dx: px, dy: 0.0 }),
                (Key::ArrowUp, Action::Orbit { dx: 0.0, dy: px }),
                (Key::ArrowDown, Action::Orbit { dx: 0.0, dy: -px }),
                (Key::Plus, Action::Zoom { factor: 1.25 }),
                (Key::Equals, Action::Zoom { factor: 1.25 }),
                (Key::Minus, Action::Zoom { factor: 0.8 }),
                (Key::F, Action::Fit),
                (Key::Period, Action::Step { delta: 1 }),
                (Key::Comma, Action::Step { delta: -1 }),
            ] {
                if i.key_pressed(key) {
                    actions.push(a);
                }
            }
            if i.key_pressed(Key::O) {
                actions.push(Action::Projection {
                    orthographic: self.state.camera.projection
                        == mdlod_render::Projection::Perspective,
                });
            }
            for (key, mode) in [
                Key::Num1,
                Key::Num2,
                Key::Num3,
                Key::Num4,
                Key::Num5,
                Key::Num6,
            ]
            .into_iter()
            .zip(Mode::ALL)
            {
                if i.key_pressed(key) {
                    actions.push(Action::Mode { mode });
                }
            }
            if i.key_pressed(Key::Space) && self.state.can_play() {
                self.playing = !self.playing;
            }
        });
        for a in actions {
            self.act(a, true);
        }
    }

    fn panel(&mut self, ui: &mut egui::Ui) {
        let mut actions = vec![];
        let s = &self.state.settings;
        ui.heading("mdlod");
        ui.separator();
        ui.label("Mode (keys 1-6)");
        let mut mode = s.mode;
        egui::ComboBox::from_id_salt("mode")
            .selected_text(mode.name())
            .show_ui(ui, |ui| {
                for m in Mode::ALL {
                    ui.selectable_value(&mut mode, m, m.name());
                }
            });
        if mode != s.mode {
            actions.push(Action::Mode { mode });
        }
        let mut error = s.error_px;
        if ui
            .add(egui::Slider::new(&mut error, 0.0..=16.0).text("screen error px"))
            .changed()
        {
            actions.push(Action::ScreenError { px: error });
        }
        match s.mode {
            Mode::Sndf => {
                let mut n = s.sndf_iterations;
                if ui
                    .add(egui::Slider::new(&mut n, 1..=1024).text("S-NDF rays"))
                    .changed()
                {
                    actions.push(Action::SndfIterations { n });
                }
            }
            Mode::Supersampled => {
                let mut n = s.spp;
                if ui
                    .add(egui::Slider::new(&mut n, 1..=mdlod_render::renderer::MAX_SPP).text("spp"))
                    .changed()
                {
                    actions.push(Action::Spp { n });
                }
            }
            _ => {}
        }
        let mut target = s.target_frame_ms;
        if ui
            .add(egui::Slider::new(&mut target, 5.0..=200.0).text("target ms"))
            .changed()
        {
            actions.push(Action::TargetFrameMs { ms: target });
        }
        ui.horizontal(|ui| {
            if ui.button("Fit (F)").clicked() {
                actions.push(Action::Fit);
            }
            let ortho = self.state.camera.projection == mdlod_render::Projection::Orthographic;
            if ui.selectable_label(ortho, "Orthographic (O)").clicked() {
                actions.push(Action::Projection {
                    orthographic: !ortho,
                });
            }
        });
        ui.horizontal(|ui| {
            if ui.button("Save view").clicked() {
                actions.push(Action::SaveView {
                    path: PathBuf::from("view.json"),
                });
            }
            if ui.button("Load view").clicked() {
                actions.push(Action::LoadView {
                    path: PathBuf::from("view.json"),
                });
            }
        });
        ui.separator();
        ui.label("Lights (drag on the disk)");
        let n = s.lights.len();
        if n > 0 {
            self.light_index = self.light_index.min(n - 1);
            ui.horizontal(|ui| {
                for i in 0..n {
                    ui.selectable_value(&mut self.light_index, i, format!("{}", i + 1));
                }
            });
            if let Some(a) = light_disk(ui, &s.lights, self.light_index) {
                actions.push(a);
            }
            let mut colour = s.lights[self.light_index].colour;
            ui.horizontal(|ui| {
                if ui.color_edit_button_rgb(&mut colour).changed() {
                    actions.push(Action::LightColour {
                        index: self.light_index,
                        colour,
                    });
                }
                if ui.button("remove").clicked() {
                    actions.push(Action::RemoveLight {
                        index: self.light_index,
                    });
                }
            });
        }
        if ui.button("add light").clicked() {
            actions.push(Action::AddLight {
                light: crate::state::Light {
                    direction: [0.5, 0.3, 0.8],
                    colour: [0.4, 0.5, 1.0],
                },
            });
        }
        let mut blinn = s.specular > 0.0;
        let mut shininess = s.shininess;
        let before = (blinn, shininess);
        ui.checkbox(&mut blinn, "Blinn-Phong highlight");
        ui.add(egui::Slider::new(&mut shininess, 1.0..=256.0).text("exponent"));
        if (blinn, shininess) != before {
            actions.push(Action::Brdf {
                specular: if blinn { 0.25 } else { 0.0 },
                shininess,
            });
        }
        let mut explorer = s.explorer.is_some();
        let mut slices = s.explorer.unwrap_or(6);
        let mut disk = s.explorer_disk_deg;
        let mut tolerance = s.explorer_tolerance_deg;
        let before = (explorer, slices, disk, tolerance);
        ui.checkbox(&mut explorer, "S-NDF explorer pattern");
        ui.add_enabled(
            explorer,
            egui::Slider::new(&mut slices, 1..=12).text("slices"),
        );
        ui.add_enabled(
            explorer,
            egui::Slider::new(&mut disk, 0.0..=90.0).text("disk °"),
        );
        ui.add_enabled(
            explorer,
            egui::Slider::new(&mut tolerance, 0.0..=20.0).text("border °"),
        );
        if (explorer, slices, disk, tolerance) != before {
            actions.push(Action::Explorer {
                slices: explorer.then_some(slices),
                disk_deg: Some(disk),
                tolerance_deg: Some(tolerance),
            });
        }
        ui.label("Paint on the normal disk (S-NDF mode)");
        ui.horizontal(|ui| {
            ui.color_edit_button_rgb(&mut self.brush_colour);
            ui.add(egui::Slider::new(&mut self.brush_radius, 0.02..=0.5).text("brush"));
        });
        if let Some(a) = paint_disk(
            ui,
            s.transfer.as_deref(),
            self.brush_colour,
            self.brush_radius,
        ) {
            actions.push(a);
        }
        if s.transfer.is_some() && ui.button("clear paint").clicked() {
            actions.push(Action::ClearPaint);
        }
        ui.horizontal(|ui| {
            ui.label("environment");
            ui.text_edit_singleline(&mut self.environment_path);
        });
        ui.horizontal(|ui| {
            if ui.button("load").clicked() {
                actions.push(Action::Environment {
                    path: Some(PathBuf::from(self.environment_path.trim())),
                });
            }
            if s.environment.is_some() && ui.button("none").clicked() {
                actions.push(Action::Environment { path: None });
            }
        });
        ui.separator();
        ui.label("Data");
        for (name, file_colour) in &self.state.species {
            let st = s.style.species.iter().find(|t| &t.name == name);
            let mut visible = !st.is_some_and(|t| t.hidden);
            let mut colour = st.and_then(|t| t.colour).unwrap_or(*file_colour);
            ui.horizontal(|ui| {
                if ui.checkbox(&mut visible, name.as_str()).changed() {
                    actions.push(Action::SpeciesVisible {
                        name: name.clone(),
                        visible,
                    });
                }
                if ui.color_edit_button_rgb(&mut colour).changed() {
                    actions.push(Action::SpeciesColour {
                        name: name.clone(),
                        colour,
                    });
                }
            });
        }
        let mut scale = s.style.radius_scale;
        if ui
            .add(
                egui::Slider::new(&mut scale, 0.1..=4.0)
                    .logarithmic(true)
                    .text("radius scale"),
            )
            .changed()
        {
            actions.push(Action::RadiusScale { scale });
        }
        if let Some(first) = self.state.attributes.first() {
            let attribute = s.style.attribute.as_ref().unwrap_or(first);
            if self.state.attributes.len() > 1 {
                let mut chosen = attribute.clone();
                egui::ComboBox::from_id_salt("attribute")
                    .selected_text(&chosen)
                    .show_ui(ui, |ui| {
                        for name in &self.state.attributes {
                            ui.selectable_value(&mut chosen, name.clone(), name);
                        }
                    });
                if &chosen != attribute {
                    actions.push(Action::Attribute {
                        name: (chosen != *first).then_some(chosen),
                    });
                }
            }
            let mut by = s.style.colour_map.is_some();
            let mut map = s.style.colour_map.unwrap_or_default();
            let before = (by, map);
            ui.checkbox(&mut by, format!("colour by {attribute}"));
            egui::ComboBox::from_id_salt("colour map")
                .selected_text(map.name())
                .show_ui(ui, |ui| {
                    for m in mdlod_render::ColourMap::ALL {
                        ui.selectable_value(&mut map, m, m.name());
                    }
                });
            if (by, map) != before {
                actions.push(Action::ColourMap {
                    map: by.then_some(map),
                });
            }
        }
        if self.state.frames.len() > 1 {
            ui.separator();
            ui.label("Timestep (, and .; space plays)");
            let mut index = self.state.frame;
            let last = self.state.frames.len() - 1;
            ui.add(
                egui::Slider::new(&mut index, 0..=last).text(
                    self.state.frames[self.state.frame]
                        .timestep
                        .map_or(String::new(), |t| format!("t = {t}")),
                ),
            );
            if index != self.state.frame {
                actions.push(Action::Frame { index });
            }
            ui.checkbox(&mut self.playing, "play");
        }
        ui.separator();
        self.status(ui);
        for a in actions {
            self.act(a, true);
        }
    }

    fn status(&self, ui: &mut egui::Ui) {
        ui.label("Status");
        match &self.shown {
            Some(s) => {
                let t = &s.stats;
                let divisor = drawn_smaller(self.state.size, &s.image);
                ui.label(format!(
                    "frame {:.0} ms{}{}{}",
                    t.frame_ms,
                    t.gpu_ms
                        .map_or(String::new(), |g| format!(" (GPU {g:.1} ms)")),
                    if s.interactive { ", moving" } else { "" },
                    if divisor > 1 {
                        format!(", drawn at 1/{divisor} size")
                    } else {
                        String::new()
                    }
                ));
                ui.label(format!(
                    "{} spp{}",
                    t.spp,
                    if s.refined { "" } else { ", refining" }
                ));
                // The error in the window's pixels, whatever size the image was drawn.
                ui.label(format!(
                    "{} particles + {} clusters, error {:.2} px",
                    t.particles,
                    t.representatives,
                    t.error_px * divisor as f32
                ));
                ui.label(format!("GPU {:.0} MiB ({})", mib(t.gpu_bytes), t.adapter));
                if let Some(b) = t.bins {
                    ui.label(bins_label(b, self.state.settings.bins));
                }
                if let Some((resident, capacity, pending)) = t.streaming {
                    ui.label(format!(
                        "streaming: {resident} of {capacity} pages resident, {pending} loading"
                    ));
                }
            }
            None => {
                ui.label("loading…");
            }
        }
        ui.label(format!("host {:.0} MiB resident", host_rss_mib()));
        ui.label(format!(
            "queue: {}{} file(s) to write",
            if self.requests.waiting() && !self.worker_gone {
                "a frame, "
            } else {
                ""
            },
            self.pending_writes
        ));
        if let Some(m) = self.requests.message() {
            ui.label(m);
        }
    }
}

fn mib(b: u64) -> f64 {
    b as f64 / (1024.0 * 1024.0)
}

fn host_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// A disk of view directions (x right, y up, the viewer at the centre) for the light
/// and painting widgets: its painter, centre and radius, and where on the unit disk a
/// click or drag happened, if one did.
fn normal_disk(ui: &mut egui::Ui) -> (egui::Painter, egui::Pos2, f32, Option<(f32, f32)>) {
    let size = 120.0;
    let (rect, response) = ui.allocate_exact_size(egui::vec2(size, size), egui::Sense::drag());
    let (c, r) = (rect.center(), size * 0.45);
    let at = (response.dragged() || response.clicked())
        .then(|| response.interact_pointer_pos())
        .flatten()
        .map(|p| ((p.x - c.x) / r, (c.y - p.y) / r));
    (ui.painter_at(rect), c, r, at)
}

/// A linear RGB colour as egui's sRGB colour.
fn srgb8(linear: [f32; 3]) -> egui::Color32 {
    let c = linear
        .map(|v| (mdlod_render::renderer::linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
    egui::Color32::from_rgb(c[0], c[1], c[2])
}

/// The light widget: every light is a dot on the disk of view directions (circled red
/// when behind the data); dragging places the selected one on the front hemisphere.
fn light_disk(
    ui: &mut egui::Ui,
    lights: &[crate::state::Light],
    selected: usize,
) -> Option<Action> {
    let (painter, c, r, at) = normal_disk(ui);
    painter.circle_filled(c, r, egui::Color32::from_gray(40));
    painter.circle_stroke(c, r, egui::Stroke::new(1.0, egui::Color32::GRAY));
    for (i, l) in lights.iter().enumerate() {
        let p = c + egui::vec2(l.direction[0], -l.direction[1]) * r;
        painter.circle_filled(p, if i == selected { 6.0 } else { 4.0 }, srgb8(l.colour));
        if l.direction[2] < 0.0 {
            painter.circle_stroke(p, 7.0, egui::Stroke::new(1.0, egui::Color32::RED));
        }
    }
    let (x, y) = at?;
    let len = (x * x + y * y).sqrt().max(1.0);
    let (x, y) = (x / len, y / len);
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    Some(Action::Light {
        index: selected,
        direction: [x, y, z],
    })
}

/// The painting widget: the normal disk showing the painted colours (mid grey where
/// nothing is painted yet); dragging paints with the brush.
fn paint_disk(
    ui: &mut egui::Ui,
    transfer: Option<&mdlod_render::sndf::TransferImage>,
    colour: [f32; 3],
    radius: f32,
) -> Option<Action> {
    let (painter, c, r, at) = normal_disk(ui);
    // A coarse mosaic of the painted image, inside the disk.
    let n = 24;
    let cell = 2.0 * r / n as f32;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (
                (i as f32 + 0.5) / n as f32 * 2.0 - 1.0,
                1.0 - (j as f32 + 0.5) / n as f32 * 2.0,
            );
            if x * x + y * y > 1.0 {
                continue;
            }
            let lin = match transfer {
                Some(t) => {
                    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
                    t.colour(mdlod_render::glam::Vec3::new(x, y, z))
                }
                None => [0.5; 3],
            };
            let min = c - egui::vec2(r, r) + egui::vec2(i as f32 * cell, j as f32 * cell);
            painter.rect_filled(
                egui::Rect::from_min_size(min, egui::vec2(cell + 0.5, cell + 0.5)),
                0.0,
                srgb8(lin),
            );
        }
    }
    painter.circle_stroke(c, r, egui::Stroke::new(1.0, egui::Color32::GRAY));
    let (x, y) = at?;
    Some(Action::Paint {
        x: x.clamp(-1.0, 1.0),
        y: y.clamp(-1.0, 1.0),
        radius,
        colour,
    })
}

impl eframe::App for ViewerApp {
    /// The window is closing: the render thread is given a moment to end (and drop its
    /// device before the process exits), then left to end with the process, not waited
    /// for (a density frame on a software driver takes many seconds, which the close
    /// would wait out).
    fn on_exit(&mut self) {
        self.worker.finish_within(EXIT_WAIT);
    }

    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.receive(&ctx);
        egui::Panel::left("controls")
            .resizable(false)
            .exact_size(PANEL_WIDTH)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.panel(ui));
            });
        let mut actions = vec![];
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE)
            .show(ui, |ui| {
                let rect = ui.available_rect_before_wrap();
                let ppp = ctx.pixels_per_point();
                let size = [
                    (rect.width() * ppp).round().max(1.0) as u32,
                    (rect.height() * ppp).round().max(1.0) as u32,
                ];
                if size != self.state.size {
                    self.state.size = size;
                    self.dirty.scene = true;
                }
                let response = ui.allocate_rect(rect, egui::Sense::click_and_drag());
                if let Some(t) = &self.texture {
                    ui.painter().image(
                        t.id(),
                        rect,
                        egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                        egui::Color32::WHITE,
                    );
                }
                let d = response.drag_delta() * ppp;
                if d != egui::Vec2::ZERO {
                    if response.dragged_by(egui::PointerButton::Primary) {
                        actions.push(Action::Orbit { dx: d.x, dy: d.y });
                    } else {
                        actions.push(Action::Pan { dx: d.x, dy: d.y });
                    }
                }
                if response.hovered() {
                    let scroll = ctx.input(|i| i.smooth_scroll_delta().y);
                    if scroll != 0.0 {
                        actions.push(Action::Zoom {
                            factor: (scroll * 0.003).exp(),
                        });
                    }
                }
            });
        for a in actions {
            self.act(a, true);
        }
        self.keys(&ctx);
        let scripted = self.step_script(&ctx);
        if self.playing && self.settled() && self.last_step.elapsed() > Duration::from_millis(200) {
            self.last_step = Instant::now();
            self.act(Action::Step { delta: 1 }, false);
        }
        if self.dirty.scene || self.dirty.lighting {
            self.send_render();
        } else if self.previewing() && !self.moving() {
            // The user stopped: the refined frame.
            self.dirty.scene = true;
            self.send_render();
        }
        let busy = !self.worker_gone && (self.moving() || self.playing || self.previewing());
        if scripted || busy {
            ctx.request_repaint_after(Duration::from_millis(16));
        }
    }
}

/// How many times smaller on each side than the window (`size`) `image` was drawn, to
/// the nearest whole number: a coarse preview's divisor (see
/// [`crate::state::preview_divisor`]), 1 for an image of the window's size or of a size
/// the window had a moment ago.
fn drawn_smaller(size: [u32; 2], image: &RgbaImage) -> u32 {
    let w = image.width.max(1);
    ((size[0] + w / 2) / w).max(1)
}

/// S-MIP levels to coarsen an orthographic S-NDF view by while dragging: one per
/// doubling of the preview's screen error over the settled one (the adaptation that
/// holds the target frame time), at most [`SMIP_MAX_COARSEN`].
pub fn coarsen_levels(moving_error_px: f32, error_px: f32) -> u32 {
    let ratio = moving_error_px / error_px.max(0.25);
    if ratio.is_finite() && ratio >= 2.0 {
        (ratio.log2().floor() as u32).min(SMIP_MAX_COARSEN)
    } else {
        0
    }
}

/// The replies waiting from the render thread, and whether it is gone (its end of the
/// channel dropped: it panicked, as it only ends otherwise when the window does).
fn drain(rx: &Receiver<Reply>) -> (Vec<Reply>, bool) {
    let mut replies = vec![];
    loop {
        match rx.try_recv() {
            Ok(r) => replies.push(r),
            Err(TryRecvError::Empty) => return (replies, false),
            Err(TryRecvError::Disconnected) => return (replies, true),
        }
    }
}

/// The status line's S-NDF bins: `sampled` per axis, and the `asked` ones when the
/// adapter's buffers made the render thread halve them (a memory limit, not an error).
pub fn bins_label(sampled: u32, asked: u32) -> String {
    if sampled < asked {
        format!("S-NDF {sampled}×{sampled} bins (asked {asked}×{asked}: GPU buffer limit)")
    } else {
        format!("S-NDF {sampled}×{sampled} bins")
    }
}

#[cfg(test)]
mod tests {
    use super::{bins_label, coarsen_levels, drain};
    use crate::worker::Reply;

    #[test]
    fn halved_bins_are_shown_with_the_asked_ones() {
        assert_eq!(bins_label(8, 8), "S-NDF 8×8 bins");
        assert_eq!(
            bins_label(4, 8),
            "S-NDF 4×4 bins (asked 8×8: GPU buffer limit)"
        );
    }

    #[test]
    fn a_stopped_render_thread_is_noticed() {
        let (tx, rx) = std::sync::mpsc::channel();
        tx.send(Reply::Error {
            id: 1,
            message: "a".into(),
        })
        .unwrap();
        let (replies, gone) = drain(&rx);
        assert_eq!((replies.len(), gone), (1, false));
        tx.send(Reply::Error {
            id: 2,
            message: "b".into(),
        })
        .unwrap();
        // The thread ends (a panic drops its sender): its last replies, then the news.
        drop(tx);
        let (replies, gone) = drain(&rx);
        assert_eq!((replies.len(), gone), (1, true));
        assert!(drain(&rx).1);
    }

    #[test]
    fn slow_previews_coarsen_the_smip_level_per_doubling_of_the_error() {
        assert_eq!(coarsen_levels(1.0, 1.0), 0);
        assert_eq!(coarsen_levels(1.9, 1.0), 0);
        assert_eq!(coarsen_levels(2.0, 1.0), 1);
        assert_eq!(coarsen_levels(7.9, 1.0), 2);
        assert_eq!(coarsen_levels(64.0, 1.0), 3);
        assert_eq!(coarsen_levels(f32::NAN, 1.0), 0);
        // A settled error of zero counts as a quarter pixel.
        assert_eq!(coarsen_levels(1.0, 0.0), 2);
    }
}
