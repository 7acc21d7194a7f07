//! Clean-up on Ctrl-C and SIGTERM (what a scheduler sends at the end of a job's time):
//! the working directories of out-of-core builds and the partial output they were
//! writing are removed before the program exits with status 130.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once};

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
