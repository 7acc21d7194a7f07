//! Clean-up on Ctrl-C and SIGTERM (what a scheduler sends at the end of a job's time):
//! the working directories of out-of-core builds and the partial output they were
//! writing are removed before the program exits with status 130.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, Once};

/// Set as the clean-up starts: work failing from then on (its files vanish under it) is
/// the interruption's doing, and the program exits with 130, not with that error.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Whether an interruption's clean-up has started.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Called on an error: when it comes from an interruption, waits for the clean-up to
/// exit with 130 instead of reporting it.
pub fn defer_to_interrupt() {
    if interrupted() {
        std::thread::sleep(std::time::Duration::from_secs(30));
        std::process::exit(130);
    }
}

/// Working directories, and outputs whose hidden partial files go with them.
static TARGETS: Mutex<Vec<(PathBuf, Option<PathBuf>)>> = Mutex::new(Vec::new());

/// Removes `work_dir` (and the partial `.NAME.*.tmp` of `output`) if the program is
/// interrupted.
pub fn remove_on_interrupt(work_dir: &Path, output: Option<&Path>) {
    static INSTALL: Once = Once::new();
    TARGETS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((work_dir.to_path_buf(), output.map(Path::to_path_buf)));
    INSTALL.call_once(|| {
        // Without a handler the default action still stops the program; only the
        // clean-up is lost, so a failure to install is not an error.
        let _ = ctrlc::set_handler(|| {
            INTERRUPTED.store(true, Ordering::SeqCst);
            let targets = TARGETS.lock().unwrap_or_else(|e| e.into_inner());
            for (dir, output) in targets.iter() {
                // Workers may still add a file while the directory is being removed.
                for _ in 0..10 {
                    if std::fs::remove_dir_all(dir).is_ok() || !dir.exists() {
                        break;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                if let Some(out) = output {
                    remove_partial(out);
                }
            }
            eprintln!("interrupted: working files removed");
            std::process::exit(130);
        });
    });
}

/// Removes the hidden `.NAME.*.tmp` files the writer of `output` makes beside it.
fn remove_partial(output: &Path) {
    let Some(name) = output.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let prefix = format!(".{name}.");
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if n.starts_with(&prefix) && n.ends_with(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// A fresh working directory in `parent` for an out-of-core build, named after this host
/// and process (`.mdlod-convert-HOST-PID-XXXX`). Directories of earlier runs on this host
/// whose process is gone (killed outright, where no handler could run) are removed first;
/// other hosts' directories on a shared file system are left alone.
pub fn work_dir(parent: &Path) -> std::io::Result<tempfile::TempDir> {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .ok()
        .filter(|h| {
            !h.is_empty()
                && h.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.')
        })
        .unwrap_or_else(|| "host".into());
    let ours = format!(".mdlod-convert-{host}-");
    if let Ok(entries) = std::fs::read_dir(parent) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(rest) = name.strip_prefix(&ours) else {
                continue;
            };
            let pid = rest.split('-').next().and_then(|p| p.parse::<u32>().ok());
            if let Some(pid) = pid {
                if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
    }
    tempfile::Builder::new()
        .prefix(&format!("{ours}{}-", std::process::id()))
        .tempdir_in(parent)
}
