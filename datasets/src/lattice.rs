//! Face-centred-cubic lattices cut by simple shapes, counted exactly without visiting sites.
//!
//! An FCC lattice with cubic constant `a` is the set of points `origin + h·(X, Y, Z)` with
//! `h = a/2` and integer `X + Y + Z` even. Sites are visited plane by plane (`Z`), row by
//! row (`Y`), and along a row (`X`, step 2). For each row every [`Shape`] reduces to one
//! chord (an interval of `x`), turned into an integer `X` range, so the number of sites in
//! any region is a sum over rows of O(1) terms: exact budgets cost no pass over the sites,
//! and counting and writing use the very same ranges, so they always agree.

use std::io;

/// A solid that cuts a lattice, described by its chord along `x` for each `(y, z)`.
#[derive(Clone, Debug)]
pub(crate) enum Shape {
    /// Axis-aligned ellipsoid (a sphere when all semi-axes are equal).
    Ellipsoid { c: [f64; 3], r: [f64; 3] },
    /// A crater: a sphere of radius `r` below `c.z` continued upwards by a vertical
    /// cylinder of the same radius (a bowl with an open chimney).
    Crater { c: [f64; 3], r: f64 },
    /// A vertical cylinder of radius `r` between heights `z[0]` and `z[1]`.
    Cylinder { c: [f64; 2], r: f64, z: [f64; 2] },
}

impl Shape {
    /// `(centre, half-width)` of the open chord at `(y, z)`, if the line meets the shape.
    #[inline]
    fn chord(&self, y: f64, z: f64) -> Option<(f64, f64)> {
        match *self {
            Shape::Ellipsoid { c, r } => {
                let dy = (y - c[1]) / r[1];
                let dz = (z - c[2]) / r[2];
                let t = 1.0 - dy * dy - dz * dz;
                (t > 0.0).then(|| (c[0], r[0] * t.sqrt()))
            }
            Shape::Crater { c, r } => {
                let dy = y - c[1];
                let dz = if z < c[2] { z - c[2] } else { 0.0 };
                let t = r * r - dy * dy - dz * dz;
                (t > 0.0).then(|| (c[0], t.sqrt()))
            }
            Shape::Cylinder { c, r, z: zr } => {
                if z < zr[0] || z > zr[1] {
                    return None;
                }
                let dy = y - c[1];
                let t = r * r - dy * dy;
                (t > 0.0).then(|| (c[0], t.sqrt()))
            }
        }
    }
}

/// A finite piece of FCC lattice: an index box, optionally kept only inside one shape,
/// minus any number of shapes.
#[derive(Clone, Debug)]
pub(crate) struct Lattice {
    /// Half the cubic lattice constant (the spacing of atomic planes along each axis).
    pub h: f64,
    pub origin: [f64; 3],
    /// Inclusive index ranges along x, y and z.
    pub ix: [i64; 2],
    pub iy: [i64; 2],
    pub iz: [i64; 2],
    pub include: Option<Shape>,
    pub exclude: Vec<Shape>,
}

/// Sites of parity `p` (`X ≡ p mod 2`) in the inclusive range `[a, b]`.
#[inline]
fn count_parity(a: i64, b: i64, p: i64) -> u64 {
    if a > b {
        return 0;
    }
    let first = a + (p - a).rem_euclid(2);
    if first > b {
        0
    } else {
        ((b - first) / 2 + 1) as u64
    }
}

impl Lattice {
    /// A lattice of constant `a` spanning the index box, with nothing cut.
    pub(crate) fn block(
        a: f64,
        origin: [f64; 3],
        ix: [i64; 2],
        iy: [i64; 2],
        iz: [i64; 2],
    ) -> Self {
        Lattice {
            h: a / 2.0,
            origin,
            ix,
            iy,
            iz,
            include: None,
            exclude: Vec::new(),
        }
    }

    /// A lattice of constant `a` whose sites lie inside `shape`, whose bounding box is given.
    pub(crate) fn inside(
        a: f64,
        origin: [f64; 3],
        shape: Shape,
        lo: [f64; 3],
        hi: [f64; 3],
    ) -> Self {
        let h = a / 2.0;
        let idx = |k: usize| {
            [
                ((lo[k] - origin[k]) / h).floor() as i64,
                ((hi[k] - origin[k]) / h).ceil() as i64,
            ]
        };
        Lattice {
            h,
            origin,
            ix: idx(0),
            iy: idx(1),
            iz: idx(2),
            include: Some(shape),
            exclude: Vec::new(),
        }
    }

    /// Index range of `X` whose `x` lies strictly inside the chord `(c, w)`.
    #[inline]
    fn chord_range(&self, (c, w): (f64, f64)) -> (i64, i64) {
        let o = self.origin[0];
        (
            ((c - w - o) / self.h).floor() as i64 + 1,
            ((c + w - o) / self.h).ceil() as i64 - 1,
        )
    }

    /// The inclusive `X` ranges of row `(iy, iz)` holding sites (before the parity rule).
    fn row_ranges(&self, iy: i64, iz: i64, out: &mut Vec<(i64, i64)>, cuts: &mut Vec<(i64, i64)>) {
        out.clear();
        let y = self.origin[1] + iy as f64 * self.h;
        let z = self.origin[2] + iz as f64 * self.h;
        let (mut a, mut b) = (self.ix[0], self.ix[1]);
        if let Some(shape) = &self.include {
            match shape.chord(y, z) {
                Some(ch) => {
                    let (ca, cb) = self.chord_range(ch);
                    a = a.max(ca);
                    b = b.min(cb);
                }
                None => return,
            }
        }
        if a > b {
            return;
        }
        cuts.clear();
        for shape in &self.exclude {
            if let Some(ch) = shape.chord(y, z) {
                let r = self.chord_range(ch);
                if r.0 <= r.1 {
                    cuts.push(r);
                }
            }
        }
        if cuts.is_empty() {
            out.push((a, b));
            return;
        }
        cuts.sort_unstable();
        let mut cur = a;
        for &(s, e) in cuts.iter() {
            if e < cur {
                continue;
            }
            if s > b {
                break;
            }
            if s > cur {
                out.push((cur, s - 1));
            }
            cur = cur.max(e + 1);
        }
        if cur <= b {
            out.push((cur, b));
        }
    }

    /// Number of sites in plane `iz`.
    pub(crate) fn count_plane(&self, iz: i64) -> u64 {
        let (mut out, mut cuts) = (Vec::new(), Vec::new());
        let mut n = 0;
        for iy in self.iy[0]..=self.iy[1] {
            self.row_ranges(iy, iz, &mut out, &mut cuts);
            let p = (iy + iz).rem_euclid(2);
            n += out.iter().map(|&(a, b)| count_parity(a, b, p)).sum::<u64>();
        }
        n
    }

    /// Number of sites in the whole index box.
    pub(crate) fn count(&self) -> u64 {
        (self.iz[0]..=self.iz[1]).map(|z| self.count_plane(z)).sum()
    }

    /// Stacks planes from `iz[0]` upwards until they hold at least `budget` sites, and
    /// returns the index of the last plane needed (`iz[0] - 1` for a zero budget).
    pub(crate) fn planes_for(&self, budget: u64) -> i64 {
        let mut have = 0;
        let mut iz = self.iz[0] - 1;
        let mut empty_run = 0;
        while have < budget {
            iz += 1;
            let n = self.count_plane(iz);
            have += n;
            empty_run = if n == 0 { empty_run + 1 } else { 0 };
            assert!(empty_run < 10_000, "lattice planes hold no sites");
        }
        iz
    }

    /// Height of plane `iz`.
    pub(crate) fn plane_z(&self, iz: i64) -> f64 {
        self.origin[2] + iz as f64 * self.h
    }

    /// Calls `f` with the position of each site in order (plane, row, x), at most `limit`
    /// times.
    pub(crate) fn for_each_site(
        &self,
        limit: u64,
        mut f: impl FnMut([f64; 3]) -> io::Result<()>,
    ) -> io::Result<()> {
        let (mut out, mut cuts) = (Vec::new(), Vec::new());
        let mut left = limit;
        for iz in self.iz[0]..=self.iz[1] {
            let z = self.plane_z(iz);
            for iy in self.iy[0]..=self.iy[1] {
                let y = self.origin[1] + iy as f64 * self.h;
                self.row_ranges(iy, iz, &mut out, &mut cuts);
                let p = (iy + iz).rem_euclid(2);
                for &(a, b) in &out {
                    let mut ix = a + (p - a).rem_euclid(2);
                    while ix <= b {
                        if left == 0 {
                            return Ok(());
                        }
                        left -= 1;
                        f([self.origin[0] + ix as f64 * self.h, y, z])?;
                        ix += 2;
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn visited(l: &Lattice) -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        l.for_each_site(u64::MAX, |p| {
            v.push(p);
            Ok(())
        })
        .unwrap();
        v
    }

    #[test]
    fn full_block_has_four_sites_per_cell() {
        let l = Lattice::block(3.615, [0.0; 3], [0, 7], [0, 7], [0, 7]);
        assert_eq!(l.count(), 4 * 4 * 4 * 4);
        assert_eq!(visited(&l).len(), 256);
    }

    #[test]
    fn counts_match_visits_for_cut_shapes() {
        let mut l = Lattice::block(3.615, [0.0; 3], [0, 39], [0, 39], [0, 29]);
        l.exclude.push(Shape::Crater {
            c: [36.15, 36.15, 40.0],
            r: 18.0,
        });
        l.exclude.push(Shape::Ellipsoid {
            c: [10.0, 12.0, 13.0],
            r: [6.0, 6.0, 6.0],
        });
        l.exclude.push(Shape::Cylinder {
            c: [60.0, 10.0],
            r: 7.0,
            z: [20.0, 1e9],
        });
        // Overlapping cuts must not be subtracted twice.
        l.exclude.push(Shape::Ellipsoid {
            c: [14.0, 12.0, 13.0],
            r: [6.0, 6.0, 6.0],
        });
        let v = visited(&l);
        assert_eq!(l.count(), v.len() as u64);
        for p in &v {
            let d = [p[0] - 10.0, p[1] - 12.0, p[2] - 13.0];
            assert!(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] >= 36.0 - 1e-9);
        }
        let inside = Lattice::inside(
            4.086,
            [1.0, 2.0, 3.0],
            Shape::Ellipsoid {
                c: [1.0, 2.0, 3.0],
                r: [9.0, 9.0, 12.0],
            },
            [-8.0, -7.0, -9.0],
            [10.0, 11.0, 15.0],
        );
        assert_eq!(inside.count(), visited(&inside).len() as u64);
        assert!(inside.count() > 100);
    }

    #[test]
    fn planes_for_reaches_budget() {
        let l = Lattice::block(3.615, [0.0; 3], [0, 9], [0, 9], [0, 0]);
        // 50 sites per plane.
        assert_eq!(l.count_plane(0), 50);
        assert_eq!(l.planes_for(0), -1);
        assert_eq!(l.planes_for(50), 0);
        assert_eq!(l.planes_for(51), 1);
        assert_eq!(l.planes_for(1000), 19);
    }
}
