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

/// Working directories, removed whole.
static TARGETS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Names the process that wrote a temporary output file (`None`: not such a file).
type TempOwner = Box<dyn Fn(&str) -> Option<u32> + Send>;

/// Directories where this process writes outputs through temporary files, each with the
/// test that names a temporary file's writer: this process's are removed.
static PARTIALS: Mutex<Vec<(PathBuf, TempOwner)>> = Mutex::new(Vec::new());

/// What the interrupted command adds to its last line (what was kept, how to go on).
static SAYING: Mutex<Option<String>> = Mutex::new(None);

/// What the interrupted command still does before it exits (a batch writes the
/// manifest of the frames it finished).
type Hook = Box<dyn Fn() + Send>;
static HOOKS: Mutex<Vec<Hook>> = Mutex::new(Vec::new());

/// Runs `hook` on Ctrl-C or SIGTERM, after the working files are removed and before
/// the program exits (a handler must be installed by [`remove_on_interrupt`]).
pub fn on_interrupt_run(hook: impl Fn() + Send + 'static) {
    HOOKS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(Box::new(hook));
}

/// What an interrupted command adds to its `--json` object (a batch's counts).
type JsonFields = Box<dyn Fn() -> serde_json::Map<String, serde_json::Value> + Send>;
static JSON_FIELDS: Mutex<Option<JsonFields>> = Mutex::new(None);

/// Sets the fields an interrupted command's `--json` object carries beside `ok` and
/// `error`.
pub fn on_interrupt_json(
    fields: impl Fn() -> serde_json::Map<String, serde_json::Value> + Send + 'static,
) {
    *JSON_FIELDS.lock().unwrap_or_else(|e| e.into_inner()) = Some(Box::new(fields));
}

/// Sets what the message of an interrupted run adds (see [`remove_on_interrupt`]).
pub fn on_interrupt_say(text: impl Into<String>) {
    *SAYING.lock().unwrap_or_else(|e| e.into_inner()) = Some(text.into());
}

/// Removes `work_dir`, and this process's temporary outputs in `outputs_dir` (the files
/// whose writer `temp_owner` names as this process: `.NAME.HOST-PID-XXXXXX.tmp`, see
/// [`mdlod_format::writer::temp_file_owner`]), if the program is interrupted.
pub fn remove_on_interrupt(
    work_dir: &Path,
    outputs_dir: &Path,
    temp_owner: impl Fn(&str) -> Option<u32> + Send + 'static,
) {
    TARGETS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(work_dir.to_path_buf());
    remove_partials_on_interrupt(outputs_dir, temp_owner);
}

/// Removes this process's temporary outputs in `outputs_dir` if the program is
/// interrupted, as [`remove_on_interrupt`] does, for a command with no working directory.
pub fn remove_partials_on_interrupt(
    outputs_dir: &Path,
    temp_owner: impl Fn(&str) -> Option<u32> + Send + 'static,
) {
    static INSTALL: Once = Once::new();
    PARTIALS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((outputs_dir.to_path_buf(), Box::new(temp_owner)));
    INSTALL.call_once(|| {
        // Without a handler the default action still stops the program; only the
        // clean-up is lost, so a failure to install is not an error.
        let _ = ctrlc::set_handler(|| {
            INTERRUPTED.store(true, Ordering::SeqCst);
            let targets = TARGETS.lock().unwrap_or_else(|e| e.into_inner());
            for dir in targets.iter() {
                // Workers may still add a file while the directory is being removed.
                for _ in 0..10 {
                    if std::fs::remove_dir_all(dir).is_ok() || !dir.exists() {
                        break;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
            }
            // No thread begins an output from here on; those begun are removed.
            mdlod_format::writer::refuse_new_outputs();
            remove_own_partials();
            for hook in HOOKS.lock().unwrap_or_else(|e| e.into_inner()).iter() {
                hook();
            }
            // A worker may have been writing a manifest (its temporary file, which the
            // gate does not hold back: the hooks write one too); one begun after this
            // is a killed run's, which the next run removes.
            remove_own_partials();
            let saying = SAYING.lock().unwrap_or_else(|e| e.into_inner());
            let message = match saying.as_deref() {
                Some(text) => format!("interrupted: working files removed; {text}"),
                None => "interrupted: working files removed".to_string(),
            };
            eprintln!("{message}");
            // A script reading `--json` gets its one object, as for any failure. The lock
            // of standard output is held from the test to the exit, so that a result
            // being printed as the signal came is either printed whole before (and this
            // prints nothing) or not at all.
            // (Only in JSON mode: a text run blocked writing to a paused pipe must still
            // exit.)
            let _stdout = crate::json_failures().then(|| std::io::stdout().lock());
            if crate::json_failures() && !crate::json_printed() {
                let mut value = serde_json::json!({ "ok": false, "error": message });
                let extra = JSON_FIELDS.lock().unwrap_or_else(|e| e.into_inner());
                if let (Some(fields), Some(map)) = (extra.as_ref(), value.as_object_mut()) {
                    map.extend(fields());
                }
                crate::print_json(value);
            }
            std::process::exit(130);
        });
    });
}

/// Removes this process's temporary outputs (see [`remove_on_interrupt`]).
fn remove_own_partials() {
    let me = std::process::id();
    for (dir, owner) in PARTIALS.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if owner(&name) == Some(me) && e.file_type().is_ok_and(|t| t.is_file()) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// A fresh working directory in `parent` for an out-of-core build, named after this host
/// and process (`.mdlod-convert-HOST-PID-XXXXXX`), so that a later run can tell whether
/// its process is gone ([`remove_leftovers_of_killed_runs`]).
pub fn work_dir(parent: &Path) -> std::io::Result<tempfile::TempDir> {
    tempfile::Builder::new()
        .prefix(&format!("{}{}-", work_dir_prefix(), std::process::id()))
        .tempdir_in(parent)
        .map_err(mdlod_format::files::temp_error)
}

/// `.mdlod-convert-HOST-`: the start of this host's working directories.
fn work_dir_prefix() -> String {
    format!(".mdlod-convert-{}-", mdlod_format::writer::host_name())
}

/// Whether the process `pid` of this host has ended: `/proc/PID` is gone, or only its
/// zombie is left (killed, not yet reaped by its parent). `false` where `/proc` cannot
/// tell, and for this process.
fn process_gone(pid: u32) -> bool {
    if pid == std::process::id() || !Path::new("/proc/self").exists() {
        return false;
    }
    let proc = PathBuf::from(format!("/proc/{pid}"));
    let Ok(stat) = std::fs::read_to_string(proc.join("stat")) else {
        return !proc.exists();
    };
    // `PID (COMMAND) STATE ...`; the command may hold spaces and parentheses.
    let state = stat
        .rsplit_once(')')
        .and_then(|(_, rest)| rest.split_whitespace().next());
    let zombie = matches!(state, Some("Z" | "X"));
    // A zombie leader whose other threads still run is a live process.
    let threads = std::fs::read_dir(proc.join("task")).map_or(1, |d| d.count());
    zombie && threads <= 1
}

/// Bytes in `path` and below (links not followed).
fn size_of(path: &Path) -> u64 {
    let Ok(m) = std::fs::symlink_metadata(path) else {
        return 0;
    };
    if !m.is_dir() {
        return m.len();
    }
    std::fs::read_dir(path).map_or(0, |d| d.flatten().map(|e| size_of(&e.path())).sum())
}

/// Removes, in each of `dirs`, what runs of this host that were killed outright (where no
/// handler could run: SIGKILL, a node's out-of-memory killer) left there: working
/// directories `.mdlod-convert-HOST-PID-XXXXXX` and temporary outputs whose owner
/// `temp_owner` reads from their name (`.NAME.HOST-PID-XXXXXX.tmp`, see
/// [`mdlod_format::writer::temp_file_owner`]), of processes that are gone. Other hosts'
/// (a shared file system), live processes' and names without a process are left alone.
/// Returns what was removed, with its size in bytes.
pub fn remove_leftovers_of_killed_runs(
    dirs: &[&Path],
    temp_owner: &dyn Fn(&str) -> Option<u32>,
) -> Vec<(PathBuf, u64)> {
    let prefix = work_dir_prefix();
    let mut removed = Vec::new();
    let mut seen: Vec<PathBuf> = Vec::new();
    for dir in dirs {
        if seen.iter().any(|d| crate::commands::same_file(d, dir)) {
            continue;
        }
        seen.push(dir.to_path_buf());
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Ok(kind) = e.file_type() else {
                continue;
            };
            let owner = if kind.is_dir() {
                name.strip_prefix(&prefix)
                    .and_then(mdlod_format::writer::pid_and_random)
            } else if kind.is_file() {
                temp_owner(&name)
            } else {
                None
            };
            let Some(pid) = owner else {
                continue;
            };
            if !process_gone(pid) {
                continue;
            }
            let path = e.path();
            let size = size_of(&path);
            let gone = if kind.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            if gone.is_ok() {
                removed.push((path, size));
            }
        }
    }
    removed
}

/// [`remove_leftovers_of_killed_runs`], saying what was removed.
pub fn remove_and_report_leftovers(dirs: &[&Path], temp_owner: &dyn Fn(&str) -> Option<u32>) {
    for (path, bytes) in remove_leftovers_of_killed_runs(dirs, temp_owner) {
        println!(
            "removed working files of an interrupted run: {} ({:.1} MB)",
            path.display(),
            bytes as f64 / 1e6
        );
    }
}
