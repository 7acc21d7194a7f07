//! Progress bars on a terminal, silence in pipes.

use std::io::IsTerminal;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mdlod_preprocess::Progress;

/// A [`Progress`] that draws on stderr when it is a terminal.
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
    enabled: bool,
}

impl Bar {
    pub fn new() -> Self {
        Bar {
            bar: Mutex::new(None),
            enabled: std::io::stderr().is_terminal(),
        }
    }

    /// A bar for the renderer when stderr is a terminal; none in a pipe, so that the
    /// renderer does not wait for each submission to report it.
    pub fn for_renderer() -> Option<Arc<dyn Progress + Send + Sync>> {
        std::io::stderr()
            .is_terminal()
            .then(|| Arc::new(Bar::new()) as Arc<dyn Progress + Send + Sync>)
    }
}

impl Progress for Bar {
    fn stage(&self, name: &str, total: Option<u64>, unit: &'static str) {
        if !self.enabled {
            return;
        }
        let mut guard = self.bar.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(b) = guard.take() {
            b.finish_and_clear();
        }
        let bar = match total {
            Some(t) => ProgressBar::new(t),
            None => ProgressBar::new_spinner(),
        };
        bar.set_draw_target(ProgressDrawTarget::stderr());
        let template = match (total, unit) {
            (Some(_), "bytes") => "{msg:>20} [{bar:30}] {binary_bytes}/{binary_total_bytes} {binary_bytes_per_sec} ETA {eta}",
            (Some(_), _) => "{msg:>20} [{bar:30}] {human_pos}/{human_len} {per_sec:0} ETA {eta}",
            (None, _) => "{msg:>20} {spinner} {elapsed}",
        };
        bar.set_style(
            ProgressStyle::with_template(template)
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_message(name.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        *guard = Some(bar);
    }

    fn advance(&self, amount: u64) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            b.inc(amount);
        }
    }

    fn finish_stage(&self) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            b.finish_and_clear();
        }
    }
}
