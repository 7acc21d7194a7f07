//! The committed real LAMMPS dumps are present and match their index entries.

use std::fs;

use mdlod_datasets::{lammps_sample, lammps_sample_path, lammps_samples_dir, LAMMPS_SAMPLES};

#[test]
fn committed_samples_match_the_index() {
    let mut total = 0;
    for s in LAMMPS_SAMPLES {
        let path = lammps_sample_path(s.file);
        let bytes = fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        total += bytes.len();
        assert!(lammps_samples_dir().join(s.input).is_file(), "{}", s.input);
        assert!(s.timesteps.len() > 1, "{}: want several frames", s.file);
        if s.gzip {
            // No gzip decoder here (the crate has no dependencies): check the magic only.
            assert_eq!(&bytes[..2], &[0x1f, 0x8b], "{}", s.file);
            continue;
        }
        let text = String::from_utf8(bytes).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        if s.columns.is_empty() {
            // XYZ: count line, comment line, atoms.
            assert_eq!(lines.len() as u64, s.timesteps.len() as u64 * (s.atoms + 2));
            assert_eq!(lines[0].trim().parse::<u64>().unwrap(), s.atoms);
            continue;
        }
        let after = |item: &str| -> Vec<&str> {
            lines
                .iter()
                .enumerate()
                .filter(|(_, l)| l.starts_with(item))
                .map(|(i, _)| lines[i + 1])
                .collect()
        };
        let steps: Vec<u64> = after("ITEM: TIMESTEP")
            .iter()
            .map(|l| l.trim().parse().unwrap())
            .collect();
        assert_eq!(steps, s.timesteps, "{}", s.file);
        assert!(after("ITEM: NUMBER OF ATOMS")
            .iter()
            .all(|l| l.trim().parse::<u64>().unwrap() == s.atoms));
        let header = format!("ITEM: ATOMS {}", s.columns.join(" "));
        let box_line = format!("ITEM: BOX BOUNDS {}", s.box_bounds);
        let count = |want: &str| lines.iter().filter(|l| **l == want).count();
        assert_eq!(count(&header), s.timesteps.len(), "{}", s.file);
        assert_eq!(count(&box_line), s.timesteps.len(), "{}", s.file);
        assert_eq!(
            count("ITEM: TIME"),
            if s.time { s.timesteps.len() } else { 0 }
        );
        assert_eq!(
            after("ITEM: UNITS").first().map(|u| u.trim()),
            s.units,
            "{}",
            s.file
        );
        let id_col = s.columns.iter().position(|c| *c == "id").unwrap();
        let mut all_sorted = true;
        let mut i = 0;
        while i < lines.len() {
            if lines[i].starts_with("ITEM: ATOMS") {
                let ids: Vec<u64> = lines[i + 1..i + 1 + s.atoms as usize]
                    .iter()
                    .map(|l| {
                        let f: Vec<&str> = l.split_whitespace().collect();
                        assert_eq!(f.len(), s.columns.len(), "{}: {l}", s.file);
                        f[id_col].parse().unwrap()
                    })
                    .collect();
                all_sorted &= ids.windows(2).all(|w| w[0] < w[1]);
                i += s.atoms as usize;
            }
            i += 1;
        }
        assert_eq!(all_sorted, s.sorted, "{}", s.file);
    }
    assert!(total < 3_000_000, "samples total {total} bytes");
    assert!(lammps_sample("cu_melt.custom.dump").is_some());
    assert!(lammps_sample("nope").is_none());
}
