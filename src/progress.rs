//! Progress bars on a terminal; in a pipe or a log file (a batch job's), a line now and
//! then for stages that run long.

use std::io::IsTerminal;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mdlod_preprocess::Progress;

/// A [`Progress`] that draws on stderr when it is a terminal, and otherwise writes a line
/// to stderr as a stage past [`Log::after`] progresses, at most one per [`Log::every`] (a
/// Slurm job's log shows how far a long conversion is; short commands print nothing).
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
    enabled: bool,
    log: Option<Log>,
}

/// The lines of a stage's progress where there is no terminal.
pub struct Log {
    /// A stage says nothing before this long...
    pub after: Duration,
    /// ...and then at most once per this long, and when it ends.
    pub every: Duration,
    write: Box<dyn Fn(String) + Send + Sync>,
    state: Mutex<Option<LogStage>>,
}

struct LogStage {
    name: String,
    total: Option<u64>,
    unit: &'static str,
    done: u64,
    started: Instant,
    /// When the last line was written (`None`: none yet).
    written: Option<Instant>,
}

impl Log {
    pub fn new(after: Duration, every: Duration, write: Box<dyn Fn(String) + Send + Sync>) -> Self {
        Log {
            after,
            every,
            write,
            state: Mutex::new(None),
        }
    }

    fn stage(&self, name: &str, total: Option<u64>, unit: &'static str) {
        self.finish();
        *self.state.lock().unwrap_or_else(|e| e.into_inner()) = Some(LogStage {
            name: name.to_string(),
            total,
            unit,
            done: 0,
            started: Instant::now(),
            written: None,
        });
    }

    fn advance(&self, amount: u64) {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let Some(s) = state.as_mut() else { return };
        s.done = s.done.saturating_add(amount);
        let now = Instant::now();
        let due = match s.written {
            None => now.duration_since(s.started) >= self.after,
            Some(at) => now.duration_since(at) >= self.every,
        };
        if due {
            s.written = Some(now);
            (self.write)(s.line(now));
        }
    }

    /// Ends the stage: "done" when it completed, "stopped" when the work ended without
    /// completing it (an error: the log must not say done before the error).
    fn end(&self, completed: bool) {
        let Some(s) = self.state.lock().unwrap_or_else(|e| e.into_inner()).take() else {
            return;
        };
        let took = s.started.elapsed();
        if s.written.is_some() || took >= self.after {
            let how = if completed {
                "done in"
            } else {
                "stopped after"
            };
            (self.write)(format!("{}: {how} {}", s.name, clock(took)));
        }
    }

    fn finish(&self) {
        self.end(true);
    }
}

impl LogStage {
    fn line(&self, now: Instant) -> String {
        let elapsed = now.duration_since(self.started);
        match self.total.filter(|&t| t > 0) {
            Some(total) => {
                let share = self.done.min(total) as f64 / total as f64;
                let left = if share > 0.0 {
                    format!(
                        ", about {} left",
                        clock(elapsed.mul_f64((1.0 - share) / share))
                    )
                } else {
                    String::new()
                };
                format!(
                    "{}: {:.0}% ({} of {} {}), {} so far{left}",
                    self.name,
                    share * 100.0,
                    self.done.min(total),
                    total,
                    self.unit,
                    clock(elapsed)
                )
            }
            None => format!("{}: {} so far", self.name, clock(elapsed)),
        }
    }
}

/// `1h02m03s`, `2m05s`, `42s`.
fn clock(d: Duration) -> String {
    let s = d.as_secs();
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, s) => format!("{h}h{m:02}m{s:02}s"),
    }
}

impl Bar {
    pub fn new() -> Self {
        let terminal = std::io::stderr().is_terminal();
        Bar {
            bar: Mutex::new(None),
            enabled: terminal,
            log: (!terminal).then(|| {
                Log::new(
                    Duration::from_secs(10),
                    Duration::from_secs(30),
                    Box::new(|line| eprintln!("{line}")),
                )
            }),
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
        if let Some(log) = &self.log {
            log.stage(name, total, unit);
        }
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
        if let Some(log) = &self.log {
            log.advance(amount);
        }
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            b.inc(amount);
        }
    }

    fn finish_stage(&self) {
        if let Some(log) = &self.log {
            log.finish();
        }
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            b.finish_and_clear();
        }
    }
}

/// A stage still open when its reporter goes (the work returned early, with an error)
/// did not complete.
impl Drop for Bar {
    fn drop(&mut self) {
        if let Some(log) = &self.log {
            log.end(false);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(after: Duration, every: Duration) -> (Log, Arc<Mutex<Vec<String>>>) {
        let lines = Arc::new(Mutex::new(vec![]));
        let sink = lines.clone();
        let log = Log::new(
            after,
            every,
            Box::new(move |l| sink.lock().unwrap().push(l)),
        );
        (log, lines)
    }

    /// Stages past the delay write their progress, with the share and what is left; a
    /// stage that ends before the delay writes nothing.
    #[test]
    fn long_stages_log_their_progress_and_short_ones_nothing() {
        let (log, lines) = recording(Duration::ZERO, Duration::ZERO);
        log.stage("converting 4 frames", Some(400), "particles");
        log.advance(100);
        std::thread::sleep(Duration::from_millis(5));
        log.advance(200);
        log.finish();
        let lines = lines.lock().unwrap().clone();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(
            lines[0].starts_with("converting 4 frames: 25% (100 of 400 particles)"),
            "{lines:?}"
        );
        assert!(lines[1].contains("75% (300 of 400 particles)"), "{lines:?}");
        assert!(lines[1].contains("left"), "{lines:?}");
        assert!(
            lines[2].starts_with("converting 4 frames: done in"),
            "{lines:?}"
        );
        let (log, lines) = recording(Duration::from_secs(3600), Duration::ZERO);
        log.stage("indexing frames", Some(10), "bytes");
        log.advance(10);
        log.stage("writing", None, "bytes");
        log.finish();
        assert!(lines.lock().unwrap().is_empty());
        // A stage that ends without completing (an error) is not logged as done.
        let (log, lines) = recording(Duration::ZERO, Duration::ZERO);
        log.stage("converting 2 frames", Some(2), "frames");
        log.advance(1);
        log.end(false);
        let lines = lines.lock().unwrap().clone();
        assert!(
            lines.len() == 2 && lines[1].starts_with("converting 2 frames: stopped after"),
            "{lines:?}"
        );
        assert_eq!(clock(Duration::from_secs(3723)), "1h02m03s");
        assert_eq!(clock(Duration::from_secs(125)), "2m05s");
    }
}
