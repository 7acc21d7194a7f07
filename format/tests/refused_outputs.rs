//! `refuse_new_outputs` is for the life of the process, so it has a test binary of its
//! own: a writer begun before it keeps its temporary file, none begins after it.

use mdlod_format::writer::{refuse_new_outputs, Writer};
use mdlod_format::FormatError;

#[test]
fn no_output_begins_once_outputs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let temp_files = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .count()
    };
    let before = Writer::create(&dir.path().join("a.mdlod"), 16).unwrap();
    assert_eq!(temp_files(), 1);
    refuse_new_outputs();
    let refused = Writer::create(&dir.path().join("b.mdlod"), 16);
    assert!(
        matches!(refused, Err(FormatError::OutputsRefused)),
        "{:?}",
        refused.err()
    );
    // Only the writer begun before is there, and it goes when dropped.
    assert_eq!(temp_files(), 1);
    drop(before);
    assert_eq!(temp_files(), 0);
}
