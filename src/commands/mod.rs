//! One module per subcommand.

pub mod batch;
pub mod convert;
pub mod demo;
pub mod generate;
pub mod info;
pub mod render;
pub mod sample;
pub mod shade;
pub mod verify;
pub mod view;

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

/// A batch's manifest (`DIR/dataset.json`) where its directory is meant: the directory
/// (`.` for a bare `dataset.json`); any other path as it is.
pub fn batch_dir_of(path: PathBuf) -> PathBuf {
    // (Not there yet in a sharded directory before its merge, which the directory's
    // commands then name.)
    let parent_is_dir = path
        .parent()
        .is_none_or(|d| d.as_os_str().is_empty() || d.is_dir());
    let manifest = path
        .file_name()
        .is_some_and(|n| n == mdlod_preprocess::batch::MANIFEST)
        && (path.is_file() || (!path.exists() && parent_is_dir));
    if !manifest {
        return path;
    }
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Refuses an image name whose extension says another format than the PNG written
/// (`x.jpg` would hold PNG data under a JPEG name); a name without an extension is
/// taken as it is.
pub fn check_png_name(option: &str, output: &Path) -> Result<()> {
    match output.extension().and_then(|e| e.to_str()) {
        Some(e) if !e.eq_ignore_ascii_case("png") => bail!(
            "{option} {}: mdlod writes PNG images; name the output .png (convert it \
             afterwards for another format)",
            output.display()
        ),
        _ => Ok(()),
    }
}

/// Refuses, before any work, an output that cannot or must not be written: an existing
/// directory, or the same file as one of `inputs` (outputs are written to a temporary
/// file and renamed over the path, which would replace the input). `option` names the
/// output on the command line (`-o`, `--save-view`); `inputs` are (option, path) pairs,
/// the option empty for a positional input. A `%` piece set stands for its pieces.
/// The first bytes (up to 8, a magic number's) of the regular file at `path`; `None`
/// where there is none to open (no file, a directory, unreadable).
pub fn file_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let f = mdlod_format::files::open(path).ok()?;
    let mut head = Vec::with_capacity(8);
    f.take(8).read_to_end(&mut head).ok()?;
    Some(head)
}

/// Refuses, before any work, a file to write beside the main output into a directory
/// that takes no file (read-only, full of inodes, not ours): the picture was drawn and
/// written first, and then the command failed with it left behind. A directory that does
/// not exist yet is the caller's to judge.
pub fn check_writable_beside(option: &str, output: &Path) -> Result<()> {
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Ok(());
    }
    if let Err(e) = tempfile::Builder::new()
        .prefix(".mdlod-probe-")
        .tempfile_in(dir)
        .map_err(mdlod_format::files::temp_error)
    {
        bail!("{option} {}: cannot write there: {e}", output.display());
    }
    Ok(())
}

pub fn check_output(option: &str, output: &Path, inputs: &[(&str, &Path)]) -> Result<()> {
    if output.as_os_str() == "-" {
        bail!(
            "{option} -: mdlod writes a file, not standard output; give its name (./- for a \
             file named -)"
        );
    }
    if output.is_dir() {
        bail!(
            "{option} {}: is a directory; give the name of the file to write",
            output.display()
        );
    }
    // A device, a pipe or a symbolic link in its place would be replaced, or (the legend,
    // written in place) block: refused before any work.
    if let Err(e) = mdlod_format::files::check_replaceable(output) {
        bail!("{option} {}: {e}", output.display());
    }
    if let Some(parent) = output.parent().filter(|p| !p.as_os_str().is_empty()) {
        if parent.exists() && !parent.is_dir() {
            bail!(
                "{option} {}: {} is a file, not a directory",
                output.display(),
                parent.display()
            );
        }
    }
    for &(what, input) in inputs {
        for file in files_of(input) {
            if same_file(output, &file) {
                let named = if what.is_empty() {
                    "the input".to_string()
                } else {
                    format!("the {what} file")
                };
                bail!(
                    "{option} {} is {named} {}: writing it would replace the input; \
                     give another output path",
                    output.display(),
                    file.display()
                );
            }
        }
    }
    Ok(())
}

/// Refuses an input that is no file the readers can index: standard input (`-`) or a
/// pipe, which a reader would take for an empty file (frames are indexed in one pass
/// and read again). A path that does not exist is left to the reader's message.
pub fn check_input_file(input: &Path) -> Result<()> {
    let save_it = "the converter reads its input twice (frames are indexed, then read): \
                   save the stream to a file first";
    if input.as_os_str() == "-" && !input.exists() {
        bail!("-: reading standard input is not supported; {save_it}");
    }
    if let Ok(m) = std::fs::metadata(input) {
        if !m.is_file() && !m.is_dir() {
            bail!(
                "{}: is a pipe or device, not a file; {save_it}",
                input.display()
            );
        }
    }
    Ok(())
}

/// [`check_output`] for a batch directory: refuses an output that is an existing file,
/// and an input that lies in the output directory under a name the batch writes there
/// (`frame-<timestep>.mdlod`, `dataset*.json`, temporary `*.tmp` files).
pub fn check_batch_output(output: &Path, inputs: &[PathBuf]) -> Result<()> {
    // A link to a directory that is not there (a scratch space not mounted, a run's
    // directory removed): creating the directory would fail, "File exists".
    if let Ok(target) = std::fs::read_link(output) {
        if !output.exists() {
            bail!(
                "-o {}: is a symbolic link to {}, which does not exist: create that \
                 directory, or give another output directory",
                output.display(),
                target.display()
            );
        }
    }
    if output.exists() && !output.is_dir() {
        bail!(
            "-o {}: is not a directory (batch writes a directory of frames and a manifest)",
            output.display()
        );
    }
    for input in inputs {
        for file in files_of(input) {
            let Some(name) = file.file_name().and_then(|n| n.to_str()) else {
                continue;
            };
            let ours = mdlod_preprocess::batch::written_by_batch(name);
            let parent = match file.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            if ours && file.exists() && same_file(parent, output) {
                bail!(
                    "the input {} is in the batch directory -o {} under a name the batch \
                     writes there: give another output directory",
                    file.display(),
                    output.display()
                );
            }
        }
    }
    Ok(())
}

/// The files an input path names: the pieces of a `%` piece set, else the path itself.
fn files_of(input: &Path) -> Vec<PathBuf> {
    if mdlod_preprocess::readers::is_piece_pattern(input) {
        if let Ok(pieces) = mdlod_preprocess::readers::piece_paths(input) {
            return pieces;
        }
    }
    vec![input.to_path_buf()]
}

/// Whether `a` and `b` are the same existing file (through links and different
/// spellings of the path): the same device and inode on unix, the same canonical path
/// elsewhere. A path that does not exist is no file's.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (a.canonicalize(), b.canonicalize()) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
    }
}

/// `--threads N`: a count of worker threads, at least 1.
/// The most threads `--threads` starts: each takes a stack and a share of the memory
/// limit, and 10^5 of them took minutes to start before any work.
pub const MAX_THREADS: usize = 1024;

pub fn parse_threads(s: &str) -> Result<usize, String> {
    match whole_number(s)? {
        0 => Err("at least 1 thread (leave --threads out for one per core)".into()),
        n if n > MAX_THREADS as u64 => Err(format!(
            "at most {MAX_THREADS} threads (leave --threads out for one per core)"
        )),
        n => Ok(n as usize),
    }
}

/// A value of the data as a summary prints it: its shortest decimal form where that is
/// short (10^-4 to 10^7), else in scientific notation (a mass of 1.989e33 g, a density of
/// 5.2e-31 g/cm³, not 34 digits).
pub struct Num(pub f32);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // (A negative zero, a range's end decoded as -0, reads as 0.)
        let v = if self.0 == 0.0 { 0.0 } else { self.0 };
        if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&v.abs()) {
            write!(f, "{v}")
        } else {
            write!(f, "{v:e}")
        }
    }
}

/// A file's size for a summary: KiB below a MiB (a small sample read as `0.0 MiB`), else
/// MiB, one decimal.
pub fn size_text(bytes: u64) -> String {
    if bytes < 1 << 20 {
        format!("{:.1} KiB", bytes as f64 / 1024.0)
    } else {
        format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20))
    }
}

/// Notes a `--memory-limit` above the memory this process may have (twice the default
/// limit: the machine's, or a Slurm job's or container's allocation): the conversion
/// plans for memory the kernel or the scheduler will not give.
pub fn note_memory_limit(limit: u64) {
    let available = mdlod_preprocess::chunked::default_memory_limit().saturating_mul(2);
    if limit > available {
        println!(
            "note: --memory-limit {:.1} GiB is above the {:.1} GiB this process may have (the \
             machine's, or the job's allocation): a conversion that uses it may be killed",
            limit as f64 / f64::from(1u32 << 30),
            available as f64 / f64::from(1u32 << 30)
        );
    }
}

/// What a working directory that cannot be made in `parent` says: where, and the
/// option that placed it there (`given`: `--temp-dir`; else the output's directory).
pub fn work_dir_context(parent: &std::path::Path, given: bool) -> String {
    format!(
        "cannot create a working directory in {} ({})",
        parent.display(),
        if given {
            "the --temp-dir given"
        } else {
            "the output's directory, where the output is written too; --temp-dir moves the \
             working files elsewhere, not the output"
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A range's end decoded as a negative zero reads as 0; other numbers as ever.
    #[test]
    fn a_negative_zero_reads_as_zero() {
        assert_eq!(super::Num(-0.0).to_string(), "0");
        assert_eq!(super::Num(-1.5).to_string(), "-1.5");
        assert_eq!(super::Num(2.5e-6).to_string(), "2.5e-6");
    }

    #[test]
    fn an_output_onto_an_input_or_a_directory_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.dump");
        std::fs::write(&input, "x").unwrap();
        // The same file under another spelling of its path.
        let other = dir.path().join(".").join("in.dump");
        let e = check_output("-o", &other, &[("", &input)]).unwrap_err();
        assert!(e.to_string().contains("is the input"), "{e}");
        let e = check_output("--save-view", &input, &[("view", &input)]).unwrap_err();
        assert!(e.to_string().contains("the view file"), "{e}");
        for bad in ["x.jpg", "x.JPEG", "movie/x.tif"] {
            let e = check_png_name("-o", Path::new(bad))
                .unwrap_err()
                .to_string();
            assert!(e.contains("writes PNG images"), "{e}");
        }
        for good in ["x.png", "x.PNG", "x", "dir.d/x.png"] {
            check_png_name("-o", Path::new(good)).unwrap();
        }
        let e = check_output("-o", dir.path(), &[("", &input)]).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        // A new file, or another existing one, is fine.
        check_output("-o", &dir.path().join("new.mdlod"), &[("", &input)]).unwrap();
        let b = dir.path().join("b.mdlod");
        std::fs::write(&b, "y").unwrap();
        check_output("-o", &b, &[("", &input)]).unwrap();
        // The pieces of a `%` piece set are inputs too.
        let piece = dir.path().join("p.0.bin");
        std::fs::write(&piece, "z").unwrap();
        let e = check_output("-o", &piece, &[("", &dir.path().join("p.%.bin"))]).unwrap_err();
        assert!(e.to_string().contains("p.0.bin"), "{e}");

        // A batch directory: not a file, and not holding an input under a frame's name.
        let e = check_batch_output(&input, std::slice::from_ref(&input)).unwrap_err();
        assert!(e.to_string().contains("is not a directory"), "{e}");
        let frame = dir.path().join("frame-0.mdlod");
        std::fs::write(&frame, "w").unwrap();
        let e = check_batch_output(dir.path(), &[frame]).unwrap_err();
        assert!(e.to_string().contains("in the batch directory"), "{e}");
        check_batch_output(dir.path(), std::slice::from_ref(&input)).unwrap();
        check_batch_output(&dir.path().join("new.d"), std::slice::from_ref(&input)).unwrap();
    }
}

/// A count as scientists write one: `1000000`, `1_000_000` or `1e6` (a whole number in
/// scientific notation); anything else, a decimal comma or separator included, is named
/// with the forms that are (the standard parser said "invalid digit found in string").
pub fn whole_number(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let t = t.strip_prefix('+').unwrap_or(t);
    let bad = || {
        format!(
            "{s:?} is not a whole number from 0 (write 1000000, 1_000_000 or 1e6{})",
            if t.contains(',') { "; no commas" } else { "" }
        )
    };
    if t.starts_with('_') || t.ends_with('_') || t.contains("__") {
        return Err(bad());
    }
    let (mantissa, exponent) = match t.split_once(['e', 'E']) {
        Some((m, e)) => {
            let e = e.strip_prefix('+').unwrap_or(e);
            if e.is_empty() || !e.bytes().all(|b| b.is_ascii_digit()) {
                return Err(bad());
            }
            (m, e.parse::<u32>().map_err(|_| bad())?)
        }
        None => (t, 0),
    };
    // `2.5e6`: the digits shifted by the exponent in decimal, exactly (a double's
    // 1.1e5 is 110000.00000000001); what is left past the point must be zeros.
    let digits: String = mantissa.chars().filter(|&c| c != '_').collect();
    let (whole, fraction) = digits.split_once('.').unwrap_or((&digits, ""));
    if whole.is_empty() && fraction.is_empty()
        || !whole
            .bytes()
            .chain(fraction.bytes())
            .all(|b| b.is_ascii_digit())
    {
        return Err(bad());
    }
    let shift = exponent as usize;
    let (kept, rest) = fraction.split_at(shift.min(fraction.len()));
    if !rest.bytes().all(|b| b == b'0') {
        return Err(bad());
    }
    let zeros = shift.saturating_sub(fraction.len());
    if zeros > 20 {
        return Err(format!("{s:?} is too large (at most {})", u64::MAX));
    }
    let number = format!("{whole}{kept}{}", "0".repeat(zeros));
    let number = number.trim_start_matches('0');
    if number.is_empty() {
        return Ok(0);
    }
    number
        .parse::<u64>()
        .map_err(|_| format!("{s:?} is too large (at most {})", u64::MAX))
}

/// [`whole_number`] for an option of 32 bits.
pub fn whole_number_u32(s: &str) -> Result<u32, String> {
    let n = whole_number(s)?;
    u32::try_from(n).map_err(|_| format!("{s:?} is too large (at most {})", u32::MAX))
}

/// [`whole_number`] for an option of the machine's word.
pub fn whole_number_usize(s: &str) -> Result<usize, String> {
    let n = whole_number(s)?;
    usize::try_from(n).map_err(|_| format!("{s:?} is too large (at most {})", usize::MAX))
}

#[cfg(test)]
mod whole_number_tests {
    use super::*;

    #[test]
    fn counts_take_separators_and_scientific_notation() {
        for (s, n) in [
            ("1000000", 1_000_000),
            ("1_000_000", 1_000_000),
            ("1e6", 1_000_000),
            ("2.5E6", 2_500_000),
            ("1e+3", 1000),
            (" 42 ", 42),
            ("0", 0),
        ] {
            assert_eq!(whole_number(s), Ok(n), "{s}");
        }
        for s in [
            "1.5", "1e-3", "-1", "1,000", "1__0", "_1", "1e", "e6", "0x10", "", "1e_6", ".e3",
        ] {
            assert!(whole_number(s).is_err(), "{s}");
        }
        // Exactly, where a double's product is not whole.
        for (s, n) in [
            ("1.1e5", 110_000),
            ("2.3e5", 230_000),
            ("1.001e6", 1_001_000),
            ("1.0", 1),
            ("+100", 100),
            ("1e19", 10_000_000_000_000_000_000),
        ] {
            assert_eq!(whole_number(s), Ok(n), "{s}");
        }
        for s in ["1e20", "2e19"] {
            assert!(whole_number(s).unwrap_err().contains("too large"), "{s}");
        }
        assert!(whole_number("1,000").unwrap_err().contains("no commas"));
        assert_eq!(
            whole_number_u32("5e9").unwrap_err(),
            "\"5e9\" is too large (at most 4294967295)"
        );
    }
}
