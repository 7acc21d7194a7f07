//! Quantized relative coordinates.
//!
//! A point is stored as `bits`-bit unsigned offsets per axis from a node's centroid:
//! `position = base + scale * (q - H)` with `H = (2^bits - 1) / 2`, evaluated in single
//! precision. With `scale = max |x - base| / H` per axis the rounding error is at most
//! `scale / 2` per axis.

/// `H = (2^bits - 1) / 2`, the quantized value of an offset of zero.
pub fn half_range(bits: u32) -> f32 {
    ((1u64 << bits) - 1) as f32 / 2.0
}

/// The per-axis step that lets offsets up to `max_abs_offset` be encoded with `bits` bits.
pub fn scale_for(max_abs_offset: [f64; 3], bits: u32) -> [f32; 3] {
    let h = f64::from(half_range(bits));
    // A little headroom so that single-precision rounding of the scale never pushes the
    // largest offset outside the code range.
    max_abs_offset.map(|m| {
        if m > 0.0 {
            (m / h * (1.0 + 1e-6)) as f32
        } else {
            0.0
        }
    })
}

/// Encodes one coordinate: `clamp(round((x − base) / scale + H), 0, 2^bits − 1)`, with
/// halves rounded up.
#[inline]
pub fn encode(x: f64, base: f32, scale: f32, bits: u32) -> u16 {
    let max = ((1u32 << bits) - 1) as f64;
    let h = max / 2.0;
    if scale == 0.0 {
        return (h + 0.5) as u16;
    }
    let v = ((x - f64::from(base)) / f64::from(scale) + h).clamp(0.0, max);
    // v ≥ 0, so truncation after adding one half rounds to nearest (no libm call).
    (v + 0.5) as u16
}

/// Decodes one coordinate, exactly as every reader (and the GPU) does.
#[inline]
pub fn decode(q: u16, base: f32, scale: f32, bits: u32) -> f32 {
    base + scale * (f32::from(q) - half_range(bits))
}

/// Decodes a point.
#[inline]
pub fn decode3(q: [u16; 3], base: [f32; 3], scale: [f32; 3], bits: u32) -> [f32; 3] {
    [0, 1, 2].map(|k| decode(q[k], base[k], scale[k], bits))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_within_half_step() {
        for bits in [8, 16] {
            let base = 12.5f32;
            let max = 3.7f64;
            let s = scale_for([max; 3], bits)[0];
            // The step is the extent over the code range (with its small headroom), not
            // something coarser that this test's tolerance would follow.
            let finest = max / f64::from(half_range(bits));
            assert!(
                f64::from(s) >= finest && f64::from(s) <= finest * (1.0 + 1e-5),
                "bits {bits}: step {s} for an extent of ±{max} (finest {finest})"
            );
            let mut x = -max;
            while x <= max {
                let v = f64::from(base) + x;
                let d = decode(encode(v, base, s, bits), base, s, bits);
                let err = (f64::from(d) - v).abs();
                // half a step plus single-precision rounding of the decode
                assert!(
                    err <= f64::from(s) * 0.5 + 1e-5,
                    "bits {bits}: x {v} decoded {d} err {err} step {s}"
                );
                x += max / 997.0;
            }
        }
    }

    #[test]
    fn zero_extent_encodes_the_base() {
        let q = encode(1.0, 1.0, 0.0, 16);
        assert_eq!(decode(q, 1.0, 0.0, 16), 1.0);
    }
}
