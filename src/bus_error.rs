//! A file cut short while it is mapped. Inputs and `.mdlod` files are read through
//! memory maps; where another program truncates one while it is read (a `cp` or an
//! `rsync --inplace` over it, a run rewriting its dump), the kernel ends the process with
//! a bus error (SIGBUS) and no message. The handler installed here says what happened and
//! which files the command was given, and exits with status 1; nothing else can be done
//! safely inside a signal handler.

use std::sync::OnceLock;

/// The message, made before any file is mapped: the handler only reads it.
static MESSAGE: OnceLock<Vec<u8>> = OnceLock::new();

/// The message for the files and directories among `args` (the command line).
fn message(args: impl Iterator<Item = std::ffi::OsString>) -> String {
    let named: Vec<String> = args
        .map(std::path::PathBuf::from)
        .filter_map(|p| match std::fs::metadata(&p) {
            Ok(m) if m.is_file() => Some(p.display().to_string()),
            Ok(m) if m.is_dir() => Some(format!("a file in {}", p.display())),
            _ => None,
        })
        .collect();
    let what = match named.as_slice() {
        [] => "a file this command reads".to_string(),
        [one] => one.clone(),
        more => format!("one of {}", more.join(", ")),
    };
    format!(
        "error: {what} was cut short while mdlod read it (a bus error: files are read through \
         memory maps, and another program truncated or rewrote one in place): let the copy or \
         the run writing it finish (or write it under another name and rename it into \
         place), then run again\n"
    )
}

/// Installs the handler for this process's command line.
pub fn install() {
    let _ = MESSAGE.set(message(std::env::args_os().skip(1)).into_bytes());
    #[allow(unsafe_code)]
    // SAFETY: `on_bus_error` only reads a message made before, writes it with
    // write(2) and ends the process with _exit(2), all async-signal-safe; it never
    // returns to the faulting access.
    unsafe {
        libc::signal(
            libc::SIGBUS,
            on_bus_error as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
}

extern "C" fn on_bus_error(_: libc::c_int) {
    if let Some(m) = MESSAGE.get() {
        #[allow(unsafe_code)]
        // SAFETY: the pointer and length are those of a live, never-freed buffer.
        unsafe {
            libc::write(2, m.as_ptr().cast(), m.len());
        }
    }
    #[allow(unsafe_code)]
    // SAFETY: _exit ends the process at once, as a signal handler may.
    unsafe {
        libc::_exit(1)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_message_names_the_files_given() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("frame.mdlod");
        std::fs::write(&f, b"x").unwrap();
        let args = [
            "-o".into(),
            f.clone().into_os_string(),
            "no-such-file".into(),
        ];
        let m = super::message(args.into_iter());
        assert!(
            m.starts_with(&format!("error: {} was cut short", f.display())),
            "{m}"
        );
        let args = [
            f.clone().into_os_string(),
            dir.path().as_os_str().to_owned(),
        ];
        let m = super::message(args.into_iter());
        assert!(
            m.contains(&format!(
                "one of {}, a file in {}",
                f.display(),
                dir.path().display()
            )),
            "{m}"
        );
    }
}
