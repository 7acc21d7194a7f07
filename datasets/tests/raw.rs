//! Raw arrays as `mdlod generate --format raw` writes them.

use mdlod_datasets::{write_raw_arrays, GenerateOptions, Kind};

/// A generation that stops before its arrays are complete leaves no sidecar describing
/// them: an earlier generation's sidecar is removed before the arrays are written, and
/// the new one is renamed into place last (a batch reads raw frames by their sidecars).
#[test]
fn arrays_stopped_half_way_are_never_described_by_a_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let opts = GenerateOptions::new(Kind::Alloy, 300);
    let (sidecar, summary) = write_raw_arrays(&opts, dir.path(), "alloy", |_| {}).unwrap();
    assert_eq!(sidecar, dir.path().join("alloy.raw.json"));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&sidecar).unwrap()).unwrap();
    assert_eq!(json["particles"], summary.total_particles);
    let positions = std::fs::metadata(dir.path().join("alloy.pos.f32")).unwrap();
    assert_eq!(positions.len(), 12 * summary.total_particles);

    // The species array cannot be created (a directory holds its name): the generation
    // fails after the positions' array was begun, and the old sidecar is gone with it.
    std::fs::remove_file(dir.path().join("alloy.type.u8")).unwrap();
    std::fs::create_dir(dir.path().join("alloy.type.u8")).unwrap();
    assert!(write_raw_arrays(&opts, dir.path(), "alloy", |_| {}).is_err());
    assert!(!sidecar.exists());
    let left: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
