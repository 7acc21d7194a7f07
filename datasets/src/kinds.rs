//! The three sample kinds as [`Plan`]s. Each picks its geometry from the particle target,
//! counts every fixed part exactly (droplets, spheres, substrate, crown) and lets one
//! "filler" lattice stack atomic planes until the total is met: the filler's last plane is
//! only partly filled, which looks like a terrace.

use std::f64::consts::{PI, TAU};

use crate::lattice::{Lattice, Shape};
use crate::plan::{Body, Component, Crown, Extra, Plan};
use crate::rng::Rng;

/// Lattice constant of copper (Å).
pub const CU_LATTICE: f64 = 3.615;
/// Lattice constant of silver (Å).
pub const AG_LATTICE: f64 = 4.086;
/// Nominal lattice constant of the jittered "liquid" of the droplets kind (Å).
const LIQUID_LATTICE: f64 = 3.75;

fn sphere_volume(r: f64) -> f64 {
    4.0 / 3.0 * PI * r * r * r
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Uniform in `[lo, hi)`, or the midpoint when the range is empty.
fn span(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        rng.range(lo, hi)
    } else {
        0.5 * (lo + hi)
    }
}

/// A lattice of constant `a` filling an axis-aligned ellipsoid, with a random sub-cell
/// offset so that separate clusters do not share one global lattice.
fn cluster(rng: &mut Rng, a: f64, c: [f64; 3], r: [f64; 3], centred: bool) -> Lattice {
    let h = a / 2.0;
    let origin = if centred {
        c
    } else {
        [0, 1, 2].map(|k| c[k] + (rng.f64() - 0.5) * h)
    };
    Lattice::inside(
        a,
        origin,
        Shape::Ellipsoid { c, r },
        [0, 1, 2].map(|k| c[k] - r[k]),
        [0, 1, 2].map(|k| c[k] + r[k]),
    )
}

/// A Cu(001) slab with a hemispherical crater, a crown around it and FCC droplets above.
pub(crate) fn crater(b: u64, seed: u64) -> Plan {
    let a = CU_LATTICE;
    let h = a / 2.0;
    let rho = 4.0 / (a * a * a);
    let mut rng = Rng::stream(seed, 1, 0);
    let bf = b as f64;

    let crown_n = (0.03 * bf).round() as u64;
    let drop_target = 0.04 * bf;
    // Slab of thickness 0.4 L with a crater of radius 0.25 L, volume in units of L³.
    let shape = 0.4 - 2.0 / 3.0 * PI * 0.25f64.powi(3);
    let slab_target = (bf - crown_n as f64 - drop_target).max(1.0);
    let nx = (((slab_target / (rho * shape)).cbrt() / a).round() as i64).max(4);
    let l = nx as f64 * a;
    let r = 0.25 * l;
    let axis = [0.5 * l, 0.5 * l];

    let n_drops = ((bf.cbrt() / 3.0).round() as usize).clamp(1, 300);
    let r_mean = (drop_target / n_drops as f64 / rho / (4.0 / 3.0 * PI)).cbrt();
    let radii: Vec<f64> = (0..n_drops)
        .map(|_| (r_mean * rng.range(0.7, 1.3)).max(0.6 * a))
        .collect();
    let drop_est: f64 = radii.iter().map(|&rd| rho * sphere_volume(rd)).sum();
    let slab_est = (bf - crown_n as f64 - drop_est).max(1.0);
    let t_est = (slab_est / rho + 0.5 * sphere_volume(r)) / (l * l);
    // Planned surface height = crater centre.
    let zs = (t_est / h).round() * h;

    let mut crown = Crown {
        c: axis,
        z0: 0.0,
        r_rim: r,
        lambda: 0.3 * r,
        smax: r,
        w0: 0.35 * r,
        flare: 0.35,
        fingers: rng.range(7.0, 14.0).floor(),
        phase: rng.range(0.0, TAU),
        grow_up: 0.3 * r,
        grow_out: 0.1 * r,
        extra_slope: 0.5,
    };
    // Conservative: the surface may end a few planes above its planned height.
    let crown_top = zs + 4.0 * h + crown.smax + crown.grow_up;

    let mut drops: Vec<Component> = Vec::new();
    let mut placed: Vec<([f64; 3], f64)> = Vec::new();
    for &rd in &radii {
        for _ in 0..300 {
            let zlo = zs + 0.3 * r + rd + 4.0 * h;
            let zhi = (zs + 2.5 * r).max(zlo + 2.0 * rd);
            let z = rng.range(zlo, zhi);
            let (x, y) = if z - rd > crown_top + 2.0 {
                let m = rd + 1.0;
                (span(&mut rng, m, l - m), span(&mut rng, m, l - m))
            } else {
                let rmax = 0.8 * r - rd - 1.0;
                if rmax <= 0.0 {
                    continue;
                }
                let rr = rmax * rng.f64().sqrt();
                let (s, c) = rng.range(0.0, TAU).sin_cos();
                (axis[0] + rr * c, axis[1] + rr * s)
            };
            let p = [x, y, z];
            if placed.iter().all(|&(q, rq)| dist(p, q) > rd + rq + 3.0) {
                placed.push((p, rd));
                let lat = cluster(&mut rng, a, p, [rd; 3], false);
                let count = lat.count();
                let speed = rng.range(0.5, 2.0);
                let (dx, dy) = (x - axis[0], y - axis[1]);
                let norm = (dx * dx + dy * dy).sqrt().max(1e-9);
                let side = 0.3 * speed * rng.f64();
                let mut comp =
                    Component::lattice(1, lat, count, Extra::new(0.3 + 0.1 * speed, 0.05));
                comp.velocity = [side * dx / norm, side * dy / norm, speed];
                drops.push(comp);
                break;
            }
        }
    }
    let drop_total: u64 = drops.iter().map(|d| d.count).sum();

    let mut slab = Lattice::block(a, [0.0; 3], [0, 2 * nx - 1], [0, 2 * nx - 1], [0, 0]);
    slab.exclude.push(Shape::Crater {
        c: [axis[0], axis[1], zs],
        r,
    });
    let slab_n = b.saturating_sub(crown_n + drop_total);
    slab.iz[1] = slab.planes_for(slab_n);
    let z_top = slab.plane_z(slab.iz[1]).max(0.0);
    crown.z0 = z_top + 1.0;
    let mut slab_extra = Extra::new(0.04, 0.02);
    slab_extra.hot = Some(([axis[0], axis[1], zs - r], 0.6 * r, 0.35));

    let mut comps = vec![
        Component::lattice(1, slab, slab_n, slab_extra),
        Component {
            ty: 1,
            body: Body::Crown(crown),
            count: crown_n,
            velocity: [0.0; 3],
            extra: Extra::new(0.15, 0.08),
        },
    ];
    comps.extend(drops);
    Plan {
        comps,
        l: [l, l],
        vacuum: (0.05 * l).max(5.0),
        species: 1,
        expansion: 0.003,
    }
}

/// A Cu block with embedded Ag spheres (each on its own, centred Ag lattice).
pub(crate) fn alloy(b: u64, seed: u64) -> Plan {
    let a = CU_LATTICE;
    let h = a / 2.0;
    let rho = 4.0 / (a * a * a);
    let rho_ag = 4.0 / AG_LATTICE.powi(3);
    let gap = 1.5;
    let mut rng = Rng::stream(seed, 2, 0);
    let bf = b as f64;

    let nx = (((bf / rho).cbrt() / a).round() as i64).max(4);
    let l = nx as f64 * a;
    let n_spheres = ((bf.cbrt() / 12.0).round() as usize).clamp(1, 64);
    let r_mean = (0.15 * l * l * l / n_spheres as f64 / (4.0 / 3.0 * PI)).cbrt();
    let mut radii: Vec<f64> = (0..n_spheres)
        .map(|_| r_mean * rng.range(0.75, 1.25))
        .collect();
    radii.sort_by(|x, y| y.total_cmp(x));

    let ag_est: f64 = radii.iter().map(|&r| rho_ag * sphere_volume(r)).sum();
    let hole_vol: f64 = radii.iter().map(|&r| sphere_volume(r + gap)).sum();
    let t_est = ((bf - ag_est).max(1.0) / rho + hole_vol) / (l * l);

    let mut spheres: Vec<([f64; 3], f64)> = Vec::new();
    for &r0 in &radii {
        let mut r = r0;
        for attempt in 0..1000 {
            if attempt % 100 == 99 {
                r *= 0.85;
            }
            let m = r + gap + 1.0;
            let (zlo, zhi) = (m, t_est - m - 2.0 * h);
            if l - m <= m || zhi <= zlo {
                continue;
            }
            let p = [
                rng.range(m, l - m),
                rng.range(m, l - m),
                rng.range(zlo, zhi),
            ];
            if spheres
                .iter()
                .all(|&(q, rq)| dist(p, q) > r + rq + 2.0 * gap + 1.0)
            {
                spheres.push((p, r));
                break;
            }
        }
    }

    let ag: Vec<Component> = spheres
        .iter()
        .map(|&(c, r)| {
            let lat = cluster(&mut rng, AG_LATTICE, c, [r; 3], true);
            let n = lat.count();
            Component::lattice(2, lat, n, Extra::new(-2.85, 0.03))
        })
        .collect();
    let ag_total: u64 = ag.iter().map(|c| c.count).sum();

    let mut cu = Lattice::block(a, [0.0; 3], [0, 2 * nx - 1], [0, 2 * nx - 1], [0, 0]);
    for &(c, r) in &spheres {
        cu.exclude.push(Shape::Ellipsoid { c, r: [r + gap; 3] });
    }
    let cu_n = b.saturating_sub(ag_total);
    cu.iz[1] = cu.planes_for(cu_n);

    let species = if ag_total > 0 { 2 } else { 1 };
    let mut comps = vec![Component::lattice(1, cu, cu_n, Extra::new(-3.54, 0.03))];
    comps.extend(ag);
    Plan {
        comps,
        l: [l, l],
        // A periodic crystal: the box ends one plane spacing above the top plane.
        vacuum: h,
        species,
        expansion: 0.003,
    }
}

/// A jittered-lattice liquid film with holes on a thin Cu substrate (type 2), torn into
/// spheroidal droplets flying above it.
pub(crate) fn droplets(b: u64, seed: u64) -> Plan {
    let a_s = CU_LATTICE;
    let mut rng = Rng::stream(seed, 3, 0);
    let bf = b as f64;
    let (jitter, noise) = (0.3, 0.05);

    // Lateral size: 4 substrate planes + a film 0.12 L thick with 25 % holes ≈ 85 % of B.
    let rho_nom = 4.0 / LIQUID_LATTICE.powi(3);
    let f = |l: f64| 8.0 * (l / a_s).powi(2) + rho_nom * 0.09 * l * l * l - 0.85 * bf;
    let (mut lo, mut hi) = (0.0, 1e7);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let nx = ((lo / a_s).round() as i64).max(4);
    let l = nx as f64 * a_s;
    // The liquid lattice constant is adjusted to be periodic in the box.
    let m = ((l / LIQUID_LATTICE).round() as i64).max(4);
    let a_l = l / m as f64;
    let h_l = a_l / 2.0;
    let rho_l = 4.0 / (a_l * a_l * a_l);

    let substrate = Lattice::block(a_s, [0.0; 3], [0, 2 * nx - 1], [0, 2 * nx - 1], [0, 3]);
    let sub_n = substrate.count();
    let z0 = substrate.plane_z(3) + 2.3;

    let n_holes = ((bf.cbrt() / 10.0).round() as usize).clamp(1, 30);
    let r_hole = (0.25 * l * l / (PI * n_holes as f64)).sqrt();
    let mut holes: Vec<([f64; 2], f64)> = Vec::new();
    for _ in 0..n_holes {
        let mut r = r_hole * rng.range(0.7, 1.3);
        for attempt in 0..600 {
            if attempt % 100 == 99 {
                r *= 0.85;
            }
            let mg = r + 1.0;
            if l - mg <= mg {
                continue;
            }
            let p = [rng.range(mg, l - mg), rng.range(mg, l - mg)];
            if holes.iter().all(|&(q, rq)| {
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt() > r + rq + 3.0
            }) {
                holes.push((p, r));
                break;
            }
        }
    }
    let hole_area: f64 = holes.iter().map(|&(_, r)| PI * r * r).sum();

    let n_drops = ((bf.cbrt() / 4.0).round() as usize).clamp(1, 300);
    let r_mean = (0.15 * bf / n_drops as f64 / rho_l / (4.0 / 3.0 * PI)).cbrt();
    let shapes: Vec<(f64, f64)> = (0..n_drops)
        .map(|_| {
            let k = rng.range(0.65, 1.5);
            let r = (r_mean * rng.range(0.7, 1.3) / k.cbrt()).max(0.6 * a_l);
            (r, r * k)
        })
        .collect();
    let drop_est: f64 = shapes
        .iter()
        .map(|&(r, rz)| rho_l * 4.0 / 3.0 * PI * r * r * rz)
        .sum();
    let liquid_est = (bf - sub_n as f64 - drop_est).max(0.0);
    let top_est = z0 + liquid_est / (rho_l * (l * l - hole_area).max(1.0));

    let mut drops: Vec<Component> = Vec::new();
    let mut placed: Vec<([f64; 3], f64)> = Vec::new();
    for &(r, rz) in &shapes {
        let rb = r.max(rz);
        for _ in 0..300 {
            let zlo = top_est + rz + 3.0 + 2.0 * h_l + jitter;
            let z = rng.range(zlo, zlo + (0.5 * l).max(6.0 * r_mean));
            let mg = r + 1.0;
            let p = [span(&mut rng, mg, l - mg), span(&mut rng, mg, l - mg), z];
            if placed.iter().all(|&(q, rq)| dist(p, q) > rb + rq + 3.0) {
                placed.push((p, rb));
                let lat = cluster(&mut rng, a_l, p, [r, r, rz], false);
                let count = lat.count();
                let vz = rng.range(0.3, 1.5);
                let extra = Extra::new(1700.0 + 100.0 * vz, 200.0);
                let mut comp = Component::liquid(1, lat, count, extra, jitter, noise);
                comp.velocity = [rng.range(-0.2, 0.2) * vz, rng.range(-0.2, 0.2) * vz, vz];
                drops.push(comp);
                break;
            }
        }
    }
    let drop_total: u64 = drops.iter().map(|d| d.count).sum();

    let mut liquid = Lattice::block(a_l, [0.0, 0.0, z0], [0, 2 * m - 1], [0, 2 * m - 1], [0, 0]);
    for &(c, r) in &holes {
        liquid.exclude.push(Shape::Cylinder {
            c,
            r,
            z: [z0 - 1.0, f64::INFINITY],
        });
    }
    let liquid_n = b.saturating_sub(sub_n + drop_total);
    liquid.iz[1] = liquid.planes_for(liquid_n);

    let mut comps = vec![
        Component::lattice(2, substrate, sub_n, Extra::new(320.0, 40.0)),
        Component::liquid(
            1,
            liquid,
            liquid_n,
            Extra::new(1450.0, 150.0),
            jitter,
            noise,
        ),
    ];
    comps.extend(drops);
    Plan {
        comps,
        l: [l, l],
        vacuum: (0.05 * l).max(5.0),
        species: 2,
        expansion: 0.003,
    }
}
