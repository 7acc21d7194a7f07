//! Shared helpers of the renderer's integration tests: small `.mdlod` files made with
//! the real converter, and cut bookkeeping.
#![allow(dead_code)]

pub mod golden;

use std::path::PathBuf;

use glam::Vec3;
use mdlod_format::MdlodFile;
use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::{Frame, NoProgress, SpeciesName};
use mdlod_render::DrawList;

/// A deterministic xorshift generator giving floats in [0, 1).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1)
    }

    pub fn next_f32(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

pub fn species(names: &[&str]) -> Vec<SpeciesName> {
    names
        .iter()
        .map(|n| SpeciesName {
            name: n.to_string(),
            numeric_type: false,
            radius: None,
            ..Default::default()
        })
        .collect()
}

/// `n` particles: a few dense blobs in a sparse cloud, in a 60 Å box, three species.
pub fn cloud_frame(n: usize, seed: u64) -> Frame {
    let mut rng = Rng::new(seed);
    let blobs: Vec<[f32; 3]> = (0..5)
        .map(|_| [0; 3].map(|_| 10.0 + 40.0 * rng.next_f32()))
        .collect();
    let mut positions = Vec::with_capacity(n);
    let mut species_index = Vec::with_capacity(n);
    for i in 0..n {
        let p = if i % 3 == 0 {
            [0; 3].map(|_| 60.0 * rng.next_f32())
        } else {
            let b = blobs[i % blobs.len()];
            [0, 1, 2].map(|k| b[k] + 8.0 * (rng.next_f32() - 0.5))
        };
        positions.push(p);
        species_index.push((i % 3) as u16);
    }
    Frame {
        positions,
        species_index,
        species: species(&["Cu", "Ag", "O"]),
        ..Default::default()
    }
}

/// An FCC copper block of `n³` cells (4 atoms each), every 7th atom silver.
pub fn fcc_frame(n: usize) -> Frame {
    let positions = mdlod_datasets::fcc_block([n, n, n], 3.615);
    // Every 7th atom silver (counting from 1).
    let species_index = (1..=positions.len())
        .map(|count| u16::from(count % 7 == 0))
        .collect();
    Frame {
        positions,
        species_index,
        species: species(&["Cu", "Ag"]),
        ..Default::default()
    }
}

/// Particles at the given positions, all of one species with the given radius.
pub fn spheres_frame(positions: &[[f32; 3]]) -> Frame {
    Frame {
        positions: positions.to_vec(),
        species_index: vec![0; positions.len()],
        species: species(&["X"]),
        ..Default::default()
    }
}

/// The camera of a large data set seen whole, for a small one: the default angles, a
/// 0.5° field of view fitted to `f`'s bounds for an image of `aspect`, which puts the
/// eye thousands of particle radii away.
pub fn far_camera(
    f: &MdlodFile,
    projection: mdlod_render::Projection,
    aspect: f32,
) -> mdlod_render::Camera {
    let mut cam = mdlod_render::Camera {
        projection,
        fov_y_deg: 0.5,
        ..Default::default()
    };
    cam.fit(&mdlod_render::data_bounds(f), aspect);
    cam
}

/// Converts `frame` with the real converter into a temporary file and opens it.
pub fn make_file(
    frame: &Frame,
    build: BuildParams,
    radii: &[(&str, f32)],
) -> (tempfile::TempDir, PathBuf, MdlodFile) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.mdlod");
    let opts = ConvertOptions {
        build,
        radii: radii.iter().map(|(n, r)| (n.to_string(), *r)).collect(),
        ..Default::default()
    };
    convert_frame(frame, None, &path, &opts, &NoProgress).unwrap();
    let f = MdlodFile::open(&path).unwrap();
    (dir, path, f)
}

/// Small hierarchy parameters so that small files still have several levels.
pub fn small_build() -> BuildParams {
    BuildParams {
        max_cluster_size: 6,
        max_root_points: 16,
        ..Default::default()
    }
}

/// The particles (indices on the finest level) below point `i` of level `level`.
pub fn particles_below(f: &MdlodFile, level: usize, first: usize, count: usize) -> (usize, usize) {
    let last = f.level_count() - 1;
    let (mut a, mut b) = (first, first + count);
    for l in level..last {
        let nodes = f.level_nodes(l);
        let (na, nb) = (&nodes[a], &nodes[b - 1]);
        a = na.child_first as usize;
        b = (nb.child_first + nb.child_count) as usize;
    }
    (a, b)
}

/// How many drawn points cover each particle.
pub fn coverage(f: &MdlodFile, draw: &DrawList) -> Vec<u32> {
    let mut cover = vec![0u32; f.particle_count() as usize];
    for r in &draw.ranges {
        let (a, b) = particles_below(f, r.level as usize, r.first as usize, r.count as usize);
        for c in &mut cover[a..b] {
            *c += 1;
        }
    }
    cover
}

/// The spheres a cut draws: (key, centre, radius), decoded as the GPU does.
pub fn drawn_spheres(f: &MdlodFile, d: &DrawList) -> Vec<((u8, u32), Vec3, f32)> {
    drawn_spheres_with(f, d, mdlod_render::traversal::representative_radius)
}

pub fn drawn_spheres_with(
    f: &MdlodFile,
    d: &DrawList,
    radius_of: fn(&mdlod_format::NodeRecord) -> f32,
) -> Vec<((u8, u32), Vec3, f32)> {
    let last = f.level_count() - 1;
    let nodes = f.nodes();
    let bits = f.position_bits();
    let radii: Vec<f32> = f.metadata().species.iter().map(|s| s.radius).collect();
    let mut out = vec![];
    for r in &d.ranges {
        for i in r.first..r.first + r.count {
            let level = r.level as usize;
            let centre = if level == 0 {
                Vec3::from(nodes[0].centroid)
            } else {
                let enc = &nodes[r.quant_node as usize];
                let q = f.positions(level).get(i as usize);
                Vec3::from(mdlod_format::quantize::decode3(
                    q,
                    enc.centroid,
                    enc.quant_scale,
                    bits,
                ))
            };
            let radius = if level == last {
                radii[usize::from(f.species()[i as usize]).min(radii.len() - 1)]
            } else {
                radius_of(&nodes[f.levels()[level].node_first as usize + i as usize])
            };
            out.push(((r.level, i), centre, radius));
        }
    }
    out
}

/// One reported stage: its name and total, the units done, and whether it ended.
pub type StageLog = (String, Option<u64>, u64, bool);

/// A progress reporter that keeps the stages it is told of, in order.
#[derive(Default)]
pub struct Recorded(std::sync::Mutex<Vec<StageLog>>);

impl mdlod_render::Progress for Recorded {
    fn stage(&self, name: &str, total: Option<u64>, _unit: &'static str) {
        self.0.lock().unwrap().push((name.into(), total, 0, false));
    }
    fn advance(&self, amount: u64) {
        let mut stages = self.0.lock().unwrap();
        let current = stages.last_mut().expect("an advance before any stage");
        assert!(!current.3, "an advance after the stage ended");
        current.2 += amount;
    }
    fn finish_stage(&self) {
        self.0.lock().unwrap().last_mut().expect("no stage").3 = true;
    }
}

impl Recorded {
    /// The stages reported since the last call.
    pub fn take(&self) -> Vec<StageLog> {
        std::mem::take(&mut *self.0.lock().unwrap())
    }

    /// Since the last call: exactly one stage `name` of `total` units, all of them done,
    /// then ended.
    pub fn assert_one_stage(&self, name: &str, total: u64, case: &str) {
        assert_eq!(
            self.take(),
            [(name.to_owned(), Some(total), total, true)],
            "{case}: progress reported"
        );
    }
}
