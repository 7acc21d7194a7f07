//! A generated sample is a [`Plan`]: a list of components with exact particle counts,
//! decided once from the options, then written frame after frame.

use std::io::{self, Write};

use crate::lattice::Lattice;
use crate::rng::Rng;
use crate::sink::Sink;
use crate::BoxBounds;

/// How the scalar column is drawn for one component.
#[derive(Clone, Debug)]
pub(crate) struct Extra {
    /// Mean value.
    pub base: f64,
    /// Half-width of the (triangular) noise.
    pub spread: f64,
    /// Optional bump `amp / (1 + |p - c|² / len²)` (e.g. hot atoms near a crater).
    pub hot: Option<([f64; 3], f64, f64)>,
}

impl Extra {
    pub(crate) fn new(base: f64, spread: f64) -> Self {
        Extra {
            base,
            spread,
            hot: None,
        }
    }

    #[inline]
    fn value(&self, rng: &mut Rng, p: [f64; 3]) -> f64 {
        let mut v = self.base + self.spread * rng.tri();
        if let Some((c, len, amp)) = self.hot {
            let d2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2);
            v += amp / (1.0 + d2 / (len * len));
        }
        v
    }
}

/// The rim thrown up around a crater: random positions in a flared sheet whose density
/// falls off exponentially with height, thinning as it rises, with azimuthal fingers.
#[derive(Clone, Debug)]
pub(crate) struct Crown {
    /// Crater axis.
    pub c: [f64; 2],
    /// Height of the crown's foot (just above the surface).
    pub z0: f64,
    /// Radius of the rim at the foot.
    pub r_rim: f64,
    /// Decay height of the density.
    pub lambda: f64,
    /// Maximum height above the foot.
    pub smax: f64,
    /// Radial thickness of the sheet at the foot.
    pub w0: f64,
    /// Outward lean: radial growth per unit height.
    pub flare: f64,
    pub fingers: f64,
    pub phase: f64,
    /// Growth of the crown's top over the frames (upwards and outwards), Å.
    pub grow_up: f64,
    pub grow_out: f64,
    /// Extra-column increase from foot to top.
    pub extra_slope: f64,
}

impl Crown {
    /// Saturating growth factor of frame `f`: 0 at frame 0, towards 1 later.
    pub(crate) fn growth(f: u32) -> f64 {
        1.0 - 0.9f64.powi(f.min(10_000) as i32)
    }

    /// One crown position for frame `f`, and its relative height `t ∈ [0, 1]`.
    #[inline]
    fn sample(&self, rng: &mut Rng, g: f64) -> ([f64; 3], f64) {
        let tail = 1.0 - (-self.smax / self.lambda).exp();
        let s = -self.lambda * (1.0 - rng.f64() * tail).ln();
        let t = (s / self.smax).clamp(0.0, 1.0);
        let amp = 0.8 * t;
        let theta = loop {
            let (u, v) = rng.pair();
            let th = u * std::f64::consts::TAU;
            if v * (1.0 + amp) < 1.0 + amp * (self.fingers * th + self.phase).cos() {
                break th;
            }
        };
        let r = self.r_rim
            + s * self.flare
            + (rng.f64() - 0.5) * self.w0 * (1.0 - 0.75 * t)
            + self.grow_out * t * g;
        let z = self.z0 + s + self.grow_up * t * g;
        let (sin, cos) = theta.sin_cos();
        ([self.c[0] + r * cos, self.c[1] + r * sin, z], t)
    }

    fn z_max(&self, f: u32) -> f64 {
        self.z0 + self.smax + self.grow_up * Self::growth(f)
    }
}

#[derive(Clone, Debug)]
pub(crate) enum Body {
    /// Lattice sites, optionally jittered (a liquid): `jitter` is a fixed per-site offset
    /// (same in every frame), `noise` a fresh per-frame one, both uniform per axis.
    Lattice {
        lat: Lattice,
        jitter: f64,
        noise: f64,
    },
    Crown(Crown),
}

#[derive(Clone, Debug)]
pub(crate) struct Component {
    pub ty: u32,
    pub body: Body,
    /// Exact number of particles this component writes.
    pub count: u64,
    /// Displacement per frame, Å.
    pub velocity: [f64; 3],
    pub extra: Extra,
}

impl Component {
    pub(crate) fn lattice(ty: u32, lat: Lattice, count: u64, extra: Extra) -> Self {
        Component {
            ty,
            body: Body::Lattice {
                lat,
                jitter: 0.0,
                noise: 0.0,
            },
            count,
            velocity: [0.0; 3],
            extra,
        }
    }

    pub(crate) fn liquid(
        ty: u32,
        lat: Lattice,
        count: u64,
        extra: Extra,
        jitter: f64,
        noise: f64,
    ) -> Self {
        Component {
            ty,
            body: Body::Lattice { lat, jitter, noise },
            count,
            velocity: [0.0; 3],
            extra,
        }
    }

    /// Highest `z` of frame `f` before the frame's scale is applied.
    fn z_max(&self, f: u32) -> f64 {
        let top = match &self.body {
            Body::Lattice { lat, jitter, noise } => lat.plane_z(lat.iz[1]) + jitter + noise,
            Body::Crown(c) => c.z_max(f),
        };
        top + self.velocity[2].max(0.0) * f as f64
    }

    fn emit<W: Write + ?Sized>(
        &self,
        index: usize,
        seed: u64,
        f: u32,
        scale: f64,
        sink: &mut Sink<W>,
    ) -> io::Result<()> {
        let idx = index as u64;
        let mut xr = Rng::stream(seed, 0x100 + idx, f as u64);
        let d = self.velocity.map(|v| v * f as f64);
        let ty = self.ty;
        match &self.body {
            Body::Lattice { lat, jitter, noise } => {
                let (jitter, noise) = (*jitter, *noise);
                let mut jr = Rng::stream(seed, 0x200 + idx, 0);
                let mut nr = Rng::stream(seed, 0x300 + idx, f as u64);
                lat.for_each_site(self.count, |mut p| {
                    if jitter > 0.0 {
                        let (j0, j1) = jr.pair();
                        let (j2, _) = jr.pair();
                        let (n0, n1) = nr.pair();
                        let (n2, _) = nr.pair();
                        p[0] += jitter * (2.0 * j0 - 1.0) + noise * (2.0 * n0 - 1.0);
                        p[1] += jitter * (2.0 * j1 - 1.0) + noise * (2.0 * n1 - 1.0);
                        p[2] += jitter * (2.0 * j2 - 1.0) + noise * (2.0 * n2 - 1.0);
                    }
                    let e = self.extra.value(&mut xr, p);
                    sink.atom(
                        ty,
                        [
                            (p[0] + d[0]) * scale,
                            (p[1] + d[1]) * scale,
                            (p[2] + d[2]) * scale,
                        ],
                        e,
                    )
                })
            }
            Body::Crown(c) => {
                let mut pr = Rng::stream(seed, 0x400 + idx, 0);
                let g = Crown::growth(f);
                for _ in 0..self.count {
                    let (p, t) = c.sample(&mut pr, g);
                    let e = self.extra.value(&mut xr, p) + c.extra_slope * t;
                    sink.atom(
                        ty,
                        [
                            (p[0] + d[0]) * scale,
                            (p[1] + d[1]) * scale,
                            (p[2] + d[2]) * scale,
                        ],
                        e,
                    )?;
                }
                Ok(())
            }
        }
    }
}

/// Everything needed to write a sample, frame after frame.
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    pub comps: Vec<Component>,
    /// Periodic lateral lengths of frame 0 (the box spans `[0, l)` in x and y).
    pub l: [f64; 2],
    /// Empty space above the highest particle.
    pub vacuum: f64,
    /// Number of atom types.
    pub species: u32,
    /// Fractional homogeneous expansion reached after many frames.
    pub expansion: f64,
}

impl Plan {
    /// Homogeneous scale factor of frame `f` (1 at frame 0; slow saturating expansion).
    pub(crate) fn scale(&self, f: u32) -> f64 {
        if f == 0 {
            1.0
        } else {
            1.0 + self.expansion * (1.0 - 0.9f64.powi(f.min(10_000) as i32))
        }
    }

    pub(crate) fn total(&self) -> u64 {
        self.comps.iter().map(|c| c.count).sum()
    }

    pub(crate) fn bounds(&self, f: u32) -> BoxBounds {
        let s = self.scale(f);
        let top = self
            .comps
            .iter()
            .filter(|c| c.count > 0)
            .map(|c| c.z_max(f))
            .fold(f64::MIN, f64::max);
        let zhi = top.max(0.0) + self.vacuum;
        BoxBounds {
            lo: [0.0; 3],
            hi: [self.l[0] * s, self.l[1] * s, zhi * s],
        }
    }

    pub(crate) fn emit<W: Write + ?Sized>(
        &self,
        seed: u64,
        f: u32,
        sink: &mut Sink<W>,
    ) -> io::Result<()> {
        let s = self.scale(f);
        for (i, c) in self.comps.iter().enumerate() {
            c.emit(i, seed, f, s, sink)?;
        }
        Ok(())
    }
}
