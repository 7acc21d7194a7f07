//! Cluster representatives (Hopf et al. 2003, Eq. 1 and Eq. 2).
//!
//! For cluster `j` with members `i` (radius `r_i`, diameter `s_i = 2 r_i`, position `x_i`):
//! - position: the radius-weighted centroid `X_j = Σ s_i x_i / Σ s_i`;
//! - size (Eq. 2): `s_j = 0.5 / (|I_j| − 1) · sqrt(Σ_{i ≠ m} s_i ‖x_i − X_j‖) + s_m` where
//!   `m` is the largest member (`s_j = s_m` for a single member), so a representative is
//!   never smaller than its largest child;
//! - flux (Eq. 1): `π/4 s_j² c_j = π/4 Σ s_i² c_i`. The flux is kept as the pair (area
//!   `A_j = Σ A_i` with `A_i = r_i²` for particles, area-weighted colour
//!   `Σ A_i c_i / A_j`): flux `= π A_j · colour_j`, and a splat of size `s_j` has intensity
//!   `c_j = colour_j · A_j / r_j²`. Sums compose exactly from level to level.
//! - attribute: area-weighted mean; species: that of the member with the largest area;
//!   bounds: union of the members' bounds (at the finest level, each particle's sphere
//!   and, where the file keeps its own radius, its species' sphere too).

use mdlod_format::meta::Species;

use super::pca_split::Clusters;
use super::Particles;

/// The representatives of one level, indexed by cluster: one record per point, so that
/// gathering them in another order touches one cache line per point.
#[derive(Clone, Debug, Default)]
pub struct LevelPoints(pub Vec<Rep>);

/// The points of one level: the particles, or representatives of a finer level.
#[derive(Clone, Copy, Debug)]
pub enum Source<'a> {
    Particles(&'a Particles<'a>),
    Reps(&'a LevelPoints),
}

impl<'a> Source<'a> {
    pub fn len(&self) -> usize {
        match self {
            Source::Particles(p) => p.positions.len(),
            Source::Reps(r) => r.0.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn reps(&self) -> Option<&'a LevelPoints> {
        match self {
            Source::Reps(r) => Some(r),
            Source::Particles(_) => None,
        }
    }

    fn species_of(p: &'a Particles<'a>, i: usize) -> &'a Species {
        &p.species[usize::from(p.species_index[i])]
    }

    #[inline]
    pub fn position(&self, i: usize) -> [f32; 3] {
        match self {
            Source::Particles(p) => p.positions[i],
            Source::Reps(r) => r.0[i].position,
        }
    }

    #[inline]
    pub fn radius(&self, i: usize) -> f32 {
        match self {
            Source::Particles(p) => p
                .radii
                .map_or_else(|| Self::species_of(p, i).radius, |r| r[i]),
            Source::Reps(r) => r.0[i].radius,
        }
    }

    #[inline]
    fn colour(&self, i: usize) -> [f32; 3] {
        match self {
            Source::Particles(p) => Self::species_of(p, i).colour,
            Source::Reps(r) => r.0[i].colour,
        }
    }

    #[inline]
    fn attribute(&self, i: usize) -> f32 {
        match self {
            Source::Particles(p) => p.attribute.map_or(0.0, |a| a[i]),
            Source::Reps(r) => r.0[i].attribute,
        }
    }
}

/// Everything a representative needs of one member.
#[derive(Clone, Copy, Debug)]
struct Member {
    position: [f32; 3],
    radius: f32,
    area: f32,
    colour: [f32; 3],
    attribute: f32,
    species: u16,
    bounds: ([f32; 3], [f32; 3]),
}

impl Source<'_> {
    /// All of point `i` in one dispatch.
    #[inline]
    fn member(&self, i: usize) -> Member {
        match self {
            Source::Particles(p) => {
                let species = p.species_index[i];
                let sp = &p.species[usize::from(species)];
                let x = p.positions[i];
                let r = p.radii.map_or(sp.radius, |r| r[i]);
                // The box holds the particle's own sphere and its species' (which a
                // reader of format 1.0 draws and checks against).
                let b = r.max(sp.radius);
                Member {
                    position: x,
                    radius: r,
                    area: r * r,
                    colour: sp.colour,
                    attribute: p.attribute.map_or(0.0, |a| a[i]),
                    species,
                    bounds: (x.map(|v| v - b), x.map(|v| v + b)),
                }
            }
            Source::Reps(r) => {
                let r = &r.0[i];
                Member {
                    position: r.position,
                    radius: r.radius,
                    area: r.area,
                    colour: r.colour,
                    attribute: r.attribute,
                    species: r.species,
                    bounds: r.bounds,
                }
            }
        }
    }
}

/// One representative, computed in double precision from its members.
#[derive(Clone, Copy, Debug)]
pub struct Rep {
    pub position: [f32; 3],
    pub radius: f32,
    pub area: f32,
    pub colour: [f32; 3],
    pub attribute: f32,
    pub species: u16,
    pub bounds: ([f32; 3], [f32; 3]),
    pub rms_radius: f32,
}

impl Rep {
    /// The node record of this representative on `level`: its geometry, flux and
    /// species; the links (children, points, parent, encoding node) and the quantization
    /// scale are the caller's, zero here (one child, one point, no parent).
    pub fn node(&self, level: usize) -> mdlod_format::layout::NodeRecord {
        mdlod_format::layout::NodeRecord {
            centroid: self.position,
            radius: self.radius,
            quant_scale: [0.0; 3],
            area_sum: self.area,
            bounds_min: self.bounds.0,
            attribute: self.attribute,
            bounds_max: self.bounds.1,
            colour: mdlod_format::layout::pack_colour(self.colour),
            child_first: 0,
            child_count: 1,
            point_first: 0,
            point_count: 1,
            parent: u32::MAX,
            quant_node: 0,
            rms_radius: self.rms_radius,
            level: level as u8,
            point_level: 0,
            species: self.species,
        }
    }
}

fn representative(src: &Source<'_>, members: &[u32]) -> Rep {
    let n = members.len();
    let mut w_sum = 0.0f64;
    let mut wx = [0.0f64; 3];
    let mut x_sum = [0.0f64; 3];
    let mut area = 0.0f64;
    let mut colour = [0.0f64; 3];
    let mut attr = 0.0f64;
    let mut largest = (0usize, f32::NEG_INFINITY);
    let mut top_area = (0u16, f32::NEG_INFINITY);
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for (k, &i) in members.iter().enumerate() {
        let m = src.member(i as usize);
        let x = m.position;
        let r = m.radius;
        let a = m.area;
        let w = f64::from(r);
        w_sum += w;
        for d in 0..3 {
            wx[d] += w * f64::from(x[d]);
            x_sum[d] += f64::from(x[d]);
        }
        area += f64::from(a);
        for d in 0..3 {
            colour[d] += f64::from(a) * f64::from(m.colour[d]);
        }
        attr += f64::from(a) * f64::from(m.attribute);
        if r > largest.1 {
            largest = (k, r);
        }
        if a > top_area.1 {
            top_area = (m.species, a);
        }
        let (blo, bhi) = m.bounds;
        for d in 0..3 {
            lo[d] = lo[d].min(blo[d]);
            hi[d] = hi[d].max(bhi[d]);
        }
    }
    let centre: [f64; 3] = if w_sum > 0.0 {
        wx.map(|v| v / w_sum)
    } else {
        x_sum.map(|v| v / n as f64)
    };
    // Eq. 2 in diameters.
    let s_m = 2.0 * f64::from(largest.1);
    let mut weighted_dist = 0.0f64;
    let mut sq_dist = 0.0f64;
    for (k, &i) in members.iter().enumerate() {
        let x = src.position(i as usize);
        let d2: f64 = (0..3).map(|d| (f64::from(x[d]) - centre[d]).powi(2)).sum();
        sq_dist += d2;
        if k != largest.0 {
            weighted_dist += 2.0 * f64::from(src.radius(i as usize)) * d2.sqrt();
        }
    }
    let s_j = if n > 1 {
        0.5 / (n as f64 - 1.0) * weighted_dist.sqrt() + s_m
    } else {
        s_m
    };
    let (colour, attribute) = if area > 0.0 {
        (colour.map(|c| (c / area) as f32), (attr / area) as f32)
    } else {
        let mut c = [0.0f64; 3];
        let mut a = 0.0;
        for &i in members {
            let ci = src.colour(i as usize);
            for d in 0..3 {
                c[d] += f64::from(ci[d]) / n as f64;
            }
            a += f64::from(src.attribute(i as usize)) / n as f64;
        }
        (c.map(|v| v as f32), a as f32)
    };
    Rep {
        position: centre.map(|v| v as f32),
        radius: (s_j / 2.0) as f32,
        area: area as f32,
        colour,
        attribute,
        species: top_area.0,
        bounds: (lo, hi),
        rms_radius: (sq_dist / n as f64).sqrt() as f32,
    }
}

/// The representatives of `clusters` of the points in `src`.
pub fn representatives(src: &Source<'_>, clusters: &Clusters) -> LevelPoints {
    use rayon::prelude::*;
    let reps = (0..clusters.len())
        .into_par_iter()
        .map(|c| representative(src, clusters.members(c)))
        .collect();
    LevelPoints(reps)
}
