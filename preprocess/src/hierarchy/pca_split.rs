//! PCA splitting of one level's points into clusters (Hopf et al. 2003, section 4).
//!
//! A cluster is split by the plane through its radius-weighted centroid orthogonal to the
//! principal axis of its covariance: points with `⟨x − X, e_max⟩ ≥ 0` go to one side, the
//! rest to the other. The paper splits the cluster of largest distortion first until a
//! global bound is met; a child's distortion never exceeds its parent's, so splitting
//! every cluster that is still above a per-cluster bound gives the same kind of cut and
//! lets independent clusters be split in parallel with a result that does not depend on
//! the thread count. Here the bound is the point count: a cluster is split while it holds
//! more than `max_cluster_size` points.
//!
//! Degenerate clusters — exact duplicates, or all points on one side of the plane
//! through floating-point rounding — are split at the middle of their (deterministic)
//! order instead, so crystal lattices and duplicated points never stall the build.

/// One point being clustered.
use crate::progress::Progress;

#[derive(Clone, Copy, Debug)]
pub struct Item {
    pub position: [f32; 3],
    /// The size weight of the centroid (the radius).
    pub weight: f32,
    /// Index of the point in the level.
    pub id: u32,
}

/// The clusters of one level: cluster `c` holds points
/// `order[offsets[c]..offsets[c + 1]]` (indices into the level).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Clusters {
    pub order: Vec<u32>,
    pub offsets: Vec<u32>,
}

impl Clusters {
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn members(&self, c: usize) -> &[u32] {
        &self.order[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }
}

/// Clusters below this size are split on the current thread.
const PARALLEL_MIN: usize = 1 << 15;

/// Splits `items` into clusters of at most `max_cluster_size` points.
/// `progress` advances by the points of each finished subtree.
pub fn cluster(mut items: Vec<Item>, max_cluster_size: usize, progress: &dyn Progress) -> Clusters {
    let max = max_cluster_size.max(1);
    let n = items.len();
    let mut scratch = items.clone();
    let mut order = vec![0u32; n];
    let stats = Stats::of(
        &items,
        items
            .first()
            .map_or([0.0; 3], |i| i.position.map(f64::from)),
    );
    let sizes = split(&mut items, &mut scratch, &mut order, &stats, max, progress);
    let mut offsets = Vec::with_capacity(sizes.len() + 1);
    let mut acc = 0u32;
    offsets.push(0);
    for s in sizes {
        acc += s;
        offsets.push(acc);
    }
    Clusters { order, offsets }
}

/// Sums over a cluster's points about a shift `s` (a point near the cluster, so that the
/// sums do not cancel): enough for the weighted centroid and the covariance.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    shift: [f64; 3],
    n: f64,
    w: f64,
    wd: [f64; 3],
    d: [f64; 3],
    /// xx, xy, xz, yy, yz, zz of d dᵀ.
    dd: [f64; 6],
}

impl Stats {
    /// The sums of `items` about `shift`, in one pass. Local accumulators keep the
    /// loop in registers.
    pub fn of(items: &[Item], shift: [f64; 3]) -> Stats {
        let (mut w_sum, mut wx, mut wy, mut wz) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let (mut dx, mut dy, mut dz) = (0.0f64, 0.0f64, 0.0f64);
        let (mut xx, mut xy, mut xz, mut yy, mut yz, mut zz) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
        for it in items {
            let x = f64::from(it.position[0]) - shift[0];
            let y = f64::from(it.position[1]) - shift[1];
            let z = f64::from(it.position[2]) - shift[2];
            let w = f64::from(it.weight);
            w_sum += w;
            wx += w * x;
            wy += w * y;
            wz += w * z;
            dx += x;
            dy += y;
            dz += z;
            xx += x * x;
            xy += x * y;
            xz += x * z;
            yy += y * y;
            yz += y * z;
            zz += z * z;
        }
        Stats {
            shift,
            n: items.len() as f64,
            w: w_sum,
            wd: [wx, wy, wz],
            d: [dx, dy, dz],
            dd: [xx, xy, xz, yy, yz, zz],
        }
    }

    /// The same sums about another shift.
    fn shifted(&self, shift: [f64; 3]) -> Stats {
        let t = [0, 1, 2].map(|k| shift[k] - self.shift[k]);
        // Σ(d − t) = Σd − n t;  Σ w(d − t) = Σ wd − w t;
        // Σ(d − t)(d − t)ᵀ = Σddᵀ − t Σdᵀ − Σd tᵀ + n t tᵀ
        let idx = [
            (0, 0, 0),
            (1, 0, 1),
            (2, 0, 2),
            (3, 1, 1),
            (4, 1, 2),
            (5, 2, 2),
        ];
        let mut dd = self.dd;
        for (s, i, j) in idx {
            dd[s] += -t[i] * self.d[j] - self.d[i] * t[j] + self.n * t[i] * t[j];
        }
        Stats {
            shift,
            n: self.n,
            w: self.w,
            wd: [0, 1, 2].map(|k| self.wd[k] - self.w * t[k]),
            d: [0, 1, 2].map(|k| self.d[k] - self.n * t[k]),
            dd,
        }
    }

    /// `self − other` (both about the same shift).
    fn minus(&self, o: &Stats) -> Stats {
        Stats {
            shift: self.shift,
            n: self.n - o.n,
            w: self.w - o.w,
            wd: [0, 1, 2].map(|k| self.wd[k] - o.wd[k]),
            d: [0, 1, 2].map(|k| self.d[k] - o.d[k]),
            dd: [0, 1, 2, 3, 4, 5].map(|k| self.dd[k] - o.dd[k]),
        }
    }

    /// The weighted centroid (the plain mean when all weights are zero) and the unit
    /// principal axis of the covariance about it.
    pub fn plane(&self) -> ([f64; 3], [f64; 3]) {
        let shift = if self.w > 0.0 {
            self.wd.map(|v| v / self.w)
        } else {
            self.d.map(|v| v / self.n.max(1.0))
        };
        // A = Σ (d − D)(d − D)ᵀ = Σ ddᵀ − D Σdᵀ − Σd Dᵀ + n D Dᵀ
        let idx = [
            (0, 0, 0),
            (1, 0, 1),
            (2, 0, 2),
            (3, 1, 1),
            (4, 1, 2),
            (5, 2, 2),
        ];
        let mut a = [0.0f64; 6];
        for (s, i, j) in idx {
            a[s] = self.dd[s] - shift[i] * self.d[j] - self.d[i] * shift[j]
                + self.n * shift[i] * shift[j];
        }
        let centroid = [0, 1, 2].map(|k| self.shift[k] + shift[k]);
        (centroid, largest_eigenvector(a))
    }
}

/// Splits `items` (whose sums are `stats`) recursively; partitions go to `scratch`, which
/// then serves as the source of the next level down (the two buffers alternate). Leaves
/// write their ids to `order` at the same positions.
fn split(
    items: &mut [Item],
    scratch: &mut [Item],
    order: &mut [u32],
    stats: &Stats,
    max: usize,
    progress: &dyn Progress,
) -> Vec<u32> {
    // Small enough to split on this thread, or small enough to be a cluster already.
    if items.len() < PARALLEL_MIN || items.len() <= max {
        let mut sizes = Vec::with_capacity(items.len() / max * 2 + 1);
        split_into(items, scratch, order, stats, max, &mut sizes);
        progress.advance(items.len() as u64);
        return sizes;
    }
    let (mid, sa, sb) = partition(items, scratch, stats);
    let (sl, sr) = scratch.split_at_mut(mid);
    let (il, ir) = items.split_at_mut(mid);
    let (ol, or) = order.split_at_mut(mid);
    let (mut a, b) = rayon::join(
        || split(sl, il, ol, &sa, max, progress),
        || split(sr, ir, or, &sb, max, progress),
    );
    a.extend(b);
    a
}

fn split_into(
    items: &mut [Item],
    scratch: &mut [Item],
    order: &mut [u32],
    stats: &Stats,
    max: usize,
    sizes: &mut Vec<u32>,
) {
    if items.len() <= max {
        for (o, it) in order.iter_mut().zip(items.iter()) {
            *o = it.id;
        }
        sizes.push(items.len() as u32);
        return;
    }
    let (mid, sa, sb) = partition(items, scratch, stats);
    let (sl, sr) = scratch.split_at_mut(mid);
    let (il, ir) = items.split_at_mut(mid);
    let (ol, or) = order.split_at_mut(mid);
    split_into(sl, il, ol, &sa, max, sizes);
    split_into(sr, ir, or, &sb, max, sizes);
}

/// Writes `items` to `out` with the points on the non-negative side of the PCA plane
/// first (in their order) and the rest after them (in reverse order), and returns the
/// size of the first part (always between 1 and `len - 1`) with the sums of both parts,
/// gathered from the smaller part. Branch-free: the store goes to a selected slot.
fn partition(items: &[Item], out: &mut [Item], stats: &Stats) -> (usize, Stats, Stats) {
    let n = items.len();
    let (centroid, axis) = stats.plane();
    // Single precision is plenty to pick a side; the plane offset is folded into one
    // constant so the test is one dot product.
    let e = axis.map(|v| v as f32);
    let offset = (centroid[0] * axis[0] + centroid[1] * axis[1] + centroid[2] * axis[2]) as f32;
    let mut lo = 0usize;
    let mut hi = n;
    for it in items {
        let p = it.position;
        let left = p[0] * e[0] + p[1] * e[1] + p[2] * e[2] >= offset;
        // lo < hi holds before every write: lo + (n - hi) items were placed so far.
        // One store to a selected (not branched-to) slot.
        let dst = if left { lo } else { hi - 1 };
        out[dst] = *it;
        lo += usize::from(left);
        hi -= usize::from(!left);
    }
    if lo == 0 || lo == n {
        // Degenerate (duplicates, or rounding put everything on one side): halve the
        // cluster in its current order.
        out.copy_from_slice(items);
        let h = n / 2;
        return (
            h,
            Stats::of(&out[..h], centroid),
            Stats::of(&out[h..], centroid),
        );
    }
    // The sums of the smaller part come from a pass over it (in cache for all but the
    // largest clusters); the other part's are the rest. The right part was written back
    // to front; sums do not depend on order.
    let total = stats.shifted(centroid);
    if lo <= n - lo {
        let a = Stats::of(&out[..lo], centroid);
        let b = total.minus(&a);
        (lo, a, b)
    } else {
        let b = Stats::of(&out[lo..], centroid);
        let a = total.minus(&b);
        (lo, a, b)
    }
}

/// The weighted centroid and the unit principal axis of the points (any unit vector when
/// the covariance vanishes).
pub fn principal_plane(items: &[Item]) -> ([f64; 3], [f64; 3]) {
    Stats::of(items, items[0].position.map(f64::from)).plane()
}

/// Unit eigenvector of the largest eigenvalue of the symmetric matrix
/// `[[a0 a1 a2] [a1 a3 a4] [a2 a4 a5]]`: the eigenvalue in closed form (Smith 1961), the
/// vector as the longest cross product of two rows of `A − λI`; power iteration where
/// the largest eigenvalue is (nearly) repeated.
pub fn largest_eigenvector(a: [f64; 6]) -> [f64; 3] {
    let m = [[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]];
    let p1 = a[1] * a[1] + a[2] * a[2] + a[4] * a[4];
    let q = (a[0] + a[3] + a[5]) / 3.0;
    let p2 = (a[0] - q).powi(2) + (a[3] - q).powi(2) + (a[5] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p.is_nan() || p <= 0.0 || !p.is_finite() {
        return power_iteration(&m);
    }
    let b = |i: usize, j: usize| (m[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let lambda = q + 2.0 * p * phi.cos();
    let r = [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[i][j] - if i == j { lambda } else { 0.0 }));
    let cross = |u: [f64; 3], v: [f64; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let norm2 = |v: [f64; 3]| v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    let candidates = [cross(r[0], r[1]), cross(r[0], r[2]), cross(r[1], r[2])];
    let mut best = candidates[0];
    for c in &candidates[1..] {
        if norm2(*c) > norm2(best) {
            best = *c;
        }
    }
    // A (nearly) repeated largest eigenvalue leaves the rows nearly parallel.
    let scale = p * p;
    if norm2(best).is_nan() || norm2(best) <= 1e-12 * scale * scale {
        return power_iteration(&m);
    }
    let n = norm2(best).sqrt();
    best.map(|x| x / n)
}

fn power_iteration(m: &[[f64; 3]; 3]) -> [f64; 3] {
    let diag = [m[0][0], m[1][1], m[2][2]];
    let start = if diag[0] >= diag[1] && diag[0] >= diag[2] {
        0
    } else if diag[1] >= diag[2] {
        1
    } else {
        2
    };
    // Start off-axis a little so a start orthogonal to e_max still converges.
    let mut v = [0.1, 0.2, 0.3];
    v[start] = 1.0;
    for _ in 0..32 {
        let w = [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2]);
        let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        if norm.is_nan() || norm <= 0.0 || !norm.is_finite() {
            break;
        }
        let next = w.map(|x| x / norm);
        let delta = (0..3).map(|k| (next[k] - v[k]).abs()).fold(0.0, f64::max);
        v = next;
        if delta < 1e-9 {
            break;
        }
    }
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn items(points: &[[f32; 3]]) -> Vec<Item> {
        points
            .iter()
            .enumerate()
            .map(|(i, p)| Item {
                position: *p,
                weight: 1.0,
                id: i as u32,
            })
            .collect()
    }

    #[test]
    fn clusters_that_fit_are_not_split_at_any_cluster_size() {
        // 100 000 points along a line, clusters of at most 65 536: one split at the mean
        // makes two halves that fit (each above the size split on its own thread).
        let pts: Vec<[f32; 3]> = (0..100_000).map(|i| [i as f32, 0.0, 0.0]).collect();
        let c = cluster(items(&pts), 65_536, &crate::progress::NoProgress);
        assert_eq!(c.offsets, vec![0, 50_000, 100_000]);
    }

    #[test]
    fn eigenvector_of_elongated_cloud_is_its_long_axis() {
        let pts: Vec<[f32; 3]> = (0..100)
            .map(|i| {
                let t = i as f32 - 50.0;
                [t, 0.1 * (i % 3) as f32, 0.05 * (i % 5) as f32]
            })
            .collect();
        let (_, axis) = principal_plane(&items(&pts));
        assert!(axis[0].abs() > 0.999, "axis {axis:?}");
    }

    #[test]
    fn closed_form_matches_power_iteration() {
        let mut seed = 12345u64;
        let mut r = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..1000 {
            // A = Σ v vᵀ over a few random vectors: symmetric positive semi-definite.
            let mut a = [0.0; 6];
            for _ in 0..4 {
                let v = [r(), r() * 3.0, r() * 0.5];
                a[0] += v[0] * v[0];
                a[1] += v[0] * v[1];
                a[2] += v[0] * v[2];
                a[3] += v[1] * v[1];
                a[4] += v[1] * v[2];
                a[5] += v[2] * v[2];
            }
            let e = largest_eigenvector(a);
            let m = [[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]];
            // A e = λ e with λ the Rayleigh quotient, and λ is the largest: no unit
            // vector of the power iteration's result has a larger quotient.
            let ae = [0, 1, 2].map(|i| m[i][0] * e[0] + m[i][1] * e[1] + m[i][2] * e[2]);
            let lambda = ae[0] * e[0] + ae[1] * e[1] + ae[2] * e[2];
            let resid = (0..3)
                .map(|i| (ae[i] - lambda * e[i]).abs())
                .fold(0.0, f64::max);
            assert!(resid < 1e-6 * (1.0 + lambda), "residual {resid} for {a:?}");
            let p = power_iteration(&m);
            let ap = [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2]);
            let lp = ap[0] * p[0] + ap[1] * p[1] + ap[2] * p[2];
            assert!(lambda >= lp - 1e-6 * (1.0 + lp), "{lambda} < {lp}");
        }
    }

    #[test]
    fn diagonal_axis() {
        let e = largest_eigenvector([1.0, 1.0, 0.0, 1.0, 0.0, 0.0]);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert!((e[0].abs() - s).abs() < 1e-6 && (e[1].abs() - s).abs() < 1e-6);
    }

    #[test]
    fn clusters_cover_every_point_once_and_respect_the_size_bound() {
        let pts: Vec<[f32; 3]> = (0..1000)
            .map(|i| [(i % 10) as f32, ((i / 10) % 10) as f32, (i / 100) as f32])
            .collect();
        let c = cluster(items(&pts), 8, &crate::NoProgress);
        let mut seen = c.order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..1000).collect::<Vec<u32>>());
        for k in 0..c.len() {
            let m = c.members(k);
            assert!(!m.is_empty() && m.len() <= 8);
        }
    }

    #[test]
    fn duplicates_and_planes_terminate() {
        let pts = vec![[1.0f32, 2.0, 3.0]; 500];
        let c = cluster(items(&pts), 4, &crate::NoProgress);
        assert!(c.len() >= 125);
        let plane: Vec<[f32; 3]> = (0..400)
            .map(|i| [(i % 20) as f32, (i / 20) as f32, 0.0])
            .collect();
        let c = cluster(items(&plane), 8, &crate::NoProgress);
        assert!((0..c.len()).all(|k| c.members(k).len() <= 8));
    }

    #[test]
    fn split_is_spatially_coherent() {
        // Two far-apart blobs of four points never share a cluster of size ≤ 4.
        let mut pts = vec![];
        for i in 0..4 {
            pts.push([i as f32 * 0.1, 0.0, 0.0]);
            pts.push([100.0 + i as f32 * 0.1, 0.0, 0.0]);
        }
        let c = cluster(items(&pts), 4, &crate::NoProgress);
        for k in 0..c.len() {
            let xs: Vec<f32> = c.members(k).iter().map(|&i| pts[i as usize][0]).collect();
            assert!(xs.iter().all(|&x| x < 50.0) || xs.iter().all(|&x| x > 50.0));
        }
    }
}
