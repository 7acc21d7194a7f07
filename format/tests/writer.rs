//! The writer's file handling: nothing appears at the target until `finish`, nothing is
//! left behind by an abandoned writer, and `finish` replaces an existing file by rename.

use std::path::Path;

use mdlod_format::{FormatError, SectionKind, Writer};

/// Names of the directory's entries, sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn dropped_writer_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mdlod");
    {
        let mut w = Writer::create(&path, 16).unwrap();
        w.write_section(SectionKind::Metadata, 0, b"{}").unwrap();
        let mut s = w.section(SectionKind::Levels, 0).unwrap();
        s.write_bytes(&[0u8; 100]).unwrap();
        s.end().unwrap();
        // While writing, only the hidden temporary file exists, never the target.
        assert!(!path.exists());
        let names = entries(dir.path());
        assert_eq!(names.len(), 1, "{names:?}");
        assert!(
            names[0].starts_with(".out.mdlod.") && names[0].ends_with(".tmp"),
            "{names:?}"
        );
    }
    assert!(!path.exists());
    assert_eq!(entries(dir.path()), Vec::<String>::new());
}

#[test]
fn dropped_writer_keeps_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mdlod");
    std::fs::write(&path, b"old contents").unwrap();
    {
        let mut w = Writer::create(&path, 8).unwrap();
        w.write_section(SectionKind::Metadata, 0, b"{}").unwrap();
    }
    assert_eq!(std::fs::read(&path).unwrap(), b"old contents");
    assert_eq!(entries(dir.path()), vec!["out.mdlod".to_string()]);
}

#[test]
fn finish_replaces_an_existing_file_by_rename() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mdlod");
    std::fs::write(&path, b"old contents").unwrap();
    // A reader holding the old file open keeps seeing the old bytes: the new file is a
    // new inode renamed over the name, not the old one rewritten in place.
    let mut old = std::fs::File::open(&path).unwrap();

    let mut w = Writer::create(&path, 16).unwrap();
    w.write_section(SectionKind::Metadata, 0, b"{\"x\":1}")
        .unwrap();
    w.write_section(SectionKind::Levels, 0, &[7u8; 40]).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), b"old contents");
    w.finish().unwrap();

    let new = std::fs::read(&path).unwrap();
    assert_eq!(&new[..8], &mdlod_format::MAGIC);
    // Header, two sections each padded to 64 bytes, a table of two 32-byte entries.
    assert_eq!(new.len(), 64 + 64 + 64 + 64);
    let mut seen = Vec::new();
    std::io::Read::read_to_end(&mut old, &mut seen).unwrap();
    assert_eq!(seen, b"old contents");
    assert_eq!(entries(dir.path()), vec!["out.mdlod".to_string()]);
}

#[test]
fn bad_position_bits_and_missing_directory_are_errors_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mdlod");
    let err = Writer::create(&path, 12).err().unwrap();
    assert!(matches!(err, FormatError::Write { .. }));
    let msg = err.to_string();
    assert!(msg.contains("out.mdlod") && msg.contains("12"), "{msg}");
    assert!(!path.exists());

    let missing = dir.path().join("no-such-dir").join("out.mdlod");
    let msg = Writer::create(&missing, 16).err().unwrap().to_string();
    assert!(msg.contains("no-such-dir"), "{msg}");
}

/// A rerun replacing a result keeps the permissions its owner gave it (a private 0600
/// file stayed world-readable 0644 after the rename), and a read-only result is refused
/// before anything is written, where the rename would have replaced it.
#[cfg(unix)]
#[test]
fn replacing_keeps_the_permissions_and_refuses_a_read_only_file() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mdlod");
    let write = |bytes: &[u8]| -> Result<(), FormatError> {
        let mut w = Writer::create(&path, 16)?;
        w.write_section(SectionKind::Metadata, 0, bytes)?;
        w.finish()
    };
    write(b"{}").unwrap();
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    for private in [0o600, 0o640, 0o660] {
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(private)).unwrap();
        write(b"{\"again\":1}").unwrap();
        assert_eq!(mode(&path), private);
    }
    // A set-user-ID bit is not handed to the new contents.
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o4755)).unwrap();
    write(b"{}").unwrap();
    assert_eq!(
        std::fs::metadata(&path).unwrap().permissions().mode() & 0o7777,
        0o755
    );
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o444)).unwrap();
    let before = std::fs::read(&path).unwrap();
    let e = write(b"{}").unwrap_err().to_string();
    assert!(e.contains("out.mdlod") && e.contains("is read-only"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(entries(dir.path()), ["out.mdlod"], "nothing left behind");
}
