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

use rayon::prelude::*;

/// One point being clustered.
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
pub fn cluster(mut items: Vec<Item>, max_cluster_size: usize) -> Clusters {
    let max = max_cluster_size.max(1);
    let sizes = split(&mut items, max);
    let mut offsets = Vec::with_capacity(sizes.len() + 1);
    let mut acc = 0u32;
    offsets.push(0);
    for s in sizes {
        acc += s;
        offsets.push(acc);
    }
    let order = items.par_iter().map(|it| it.id).collect();
    Clusters { order, offsets }
}

fn split(items: &mut [Item], max: usize) -> Vec<u32> {
    if items.len() <= max {
        return vec![items.len() as u32];
    }
    if items.len() < PARALLEL_MIN {
        let mut sizes = Vec::with_capacity(items.len() / max * 2 + 1);
        split_into(items, max, &mut sizes);
        return sizes;
    }
    let mid = partition(items);
    let (left, right) = items.split_at_mut(mid);
    let (mut a, b) = rayon::join(|| split(left, max), || split(right, max));
    a.extend(b);
    a
}

fn split_into(items: &mut [Item], max: usize, sizes: &mut Vec<u32>) {
    if items.len() <= max {
        sizes.push(items.len() as u32);
        return;
    }
    let mid = partition(items);
    let (left, right) = items.split_at_mut(mid);
    split_into(left, max, sizes);
    split_into(right, max, sizes);
}

/// Reorders `items` so that the points on the non-negative side of the PCA plane come
/// first, and returns their count (always between 1 and `len - 1`).
fn partition(items: &mut [Item]) -> usize {
    let n = items.len();
    let (centroid, axis) = principal_plane(items);
    let side = |it: &Item| {
        let d = [0, 1, 2].map(|k| f64::from(it.position[k]) - centroid[k]);
        d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2] >= 0.0
    };
    let mut i = 0;
    let mut j = n;
    while i < j {
        if side(&items[i]) {
            i += 1;
        } else {
            j -= 1;
            items.swap(i, j);
        }
    }
    if i == 0 || i == n {
        n / 2
    } else {
        i
    }
}

/// The weighted centroid and the unit principal axis of the points (any unit vector when
/// the covariance vanishes).
pub fn principal_plane(items: &[Item]) -> ([f64; 3], [f64; 3]) {
    // One pass of sums about the first point (shifted to avoid cancellation).
    let x0 = items[0].position.map(f64::from);
    let mut w_sum = 0.0;
    let mut wd = [0.0f64; 3];
    let mut d_sum = [0.0f64; 3];
    let mut dd = [0.0f64; 6];
    for it in items {
        let d = [0, 1, 2].map(|k| f64::from(it.position[k]) - x0[k]);
        let w = f64::from(it.weight);
        w_sum += w;
        for k in 0..3 {
            wd[k] += w * d[k];
            d_sum[k] += d[k];
        }
        dd[0] += d[0] * d[0];
        dd[1] += d[0] * d[1];
        dd[2] += d[0] * d[2];
        dd[3] += d[1] * d[1];
        dd[4] += d[1] * d[2];
        dd[5] += d[2] * d[2];
    }
    let n = items.len() as f64;
    let shift = if w_sum > 0.0 {
        wd.map(|v| v / w_sum)
    } else {
        d_sum.map(|v| v / n)
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
        a[s] = dd[s] - shift[i] * d_sum[j] - d_sum[i] * shift[j] + n * shift[i] * shift[j];
    }
    let centroid = [0, 1, 2].map(|k| x0[k] + shift[k]);
    (centroid, largest_eigenvector(a))
}

/// Unit eigenvector of the largest eigenvalue of the symmetric matrix
/// `[[a0 a1 a2] [a1 a3 a4] [a2 a4 a5]]`, by power iteration from the axis of largest
/// variance.
pub fn largest_eigenvector(a: [f64; 6]) -> [f64; 3] {
    let m = [[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]];
    let diag = [a[0], a[3], a[5]];
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
        if !(norm > 0.0) || !norm.is_finite() {
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
        let c = cluster(items(&pts), 8);
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
        let c = cluster(items(&pts), 4);
        assert!(c.len() >= 125);
        let plane: Vec<[f32; 3]> = (0..400)
            .map(|i| [(i % 20) as f32, (i / 20) as f32, 0.0])
            .collect();
        let c = cluster(items(&plane), 8);
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
        let c = cluster(items(&pts), 4);
        for k in 0..c.len() {
            let xs: Vec<f32> = c.members(k).iter().map(|&i| pts[i as usize][0]).collect();
            assert!(xs.iter().all(|&x| x < 50.0) || xs.iter().all(|&x| x > 50.0));
        }
    }
}
