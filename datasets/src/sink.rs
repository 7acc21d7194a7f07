//! The output side: fixed-point text formatting, buffering, ids, periodic wrapping, the
//! particle cap, the `duplicates` option and progress reports.

use std::io::{self, Write};

/// Digits after the decimal point of every written float.
pub const DECIMALS: u32 = 4;
const SCALE: f64 = 10_000.0;
const FLUSH_AT: usize = 1 << 18;
/// Longest possible atom line: id, type, four signed fixed-point numbers, separators.
const LINE_MAX: usize = 20 + 1 + 10 + 4 * (1 + 21 + 1) + 1;
const PROGRESS_EVERY: u64 = 1 << 16;

const DIGIT_PAIRS: &[u8; 200] = b"\
0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// Rounds `v` to the nearest multiple of 10^-4 (half away from zero), as an integer count
/// of 10^-4 units. This is the value the text will hold.
#[inline]
pub(crate) fn quantize(v: f64) -> i64 {
    let s = v * SCALE;
    (if s >= 0.0 { s + 0.5 } else { s - 0.5 }) as i64
}

/// Writes `v` in decimal at `buf[pos..]`, returns the new position. Digits are written
/// in place from the end, two at a time (no temporary, no `memmove`).
#[inline]
fn put_u64(buf: &mut [u8], pos: usize, mut v: u64) -> usize {
    let n = v.checked_ilog10().map_or(1, |d| d as usize + 1);
    let end = pos + n;
    let out = &mut buf[pos..end];
    let mut i = n;
    while v >= 100 {
        let d = (v % 100) as usize * 2;
        v /= 100;
        i -= 2;
        out[i] = DIGIT_PAIRS[d];
        out[i + 1] = DIGIT_PAIRS[d + 1];
    }
    if v >= 10 {
        let d = v as usize * 2;
        out[0] = DIGIT_PAIRS[d];
        out[1] = DIGIT_PAIRS[d + 1];
    } else {
        out[0] = b'0' + v as u8;
    }
    end
}

/// Writes the quantized value `q` (units of 10^-4) as `[-]int.dddd`.
#[inline]
fn put_fixed4(buf: &mut [u8], mut pos: usize, q: i64) -> usize {
    if q < 0 {
        buf[pos] = b'-';
        pos += 1;
    }
    let a = q.unsigned_abs();
    let int = a / 10_000;
    if int < 10_000 {
        // Common case (|v| < 10^4) without a loop.
        let int = int as usize;
        let (h, l) = (int / 100 * 2, int % 100 * 2);
        let out = &mut buf[pos..pos + 4];
        pos += if int >= 1000 {
            out[..2].copy_from_slice(&DIGIT_PAIRS[h..h + 2]);
            out[2..].copy_from_slice(&DIGIT_PAIRS[l..l + 2]);
            4
        } else if int >= 100 {
            out[0] = DIGIT_PAIRS[h + 1];
            out[1..3].copy_from_slice(&DIGIT_PAIRS[l..l + 2]);
            3
        } else if int >= 10 {
            out[..2].copy_from_slice(&DIGIT_PAIRS[l..l + 2]);
            2
        } else {
            out[0] = DIGIT_PAIRS[l + 1];
            1
        };
    } else {
        pos = put_u64(buf, pos, int);
    }
    let frac = (a % 10_000) as usize;
    let (hi, lo) = (frac / 100 * 2, frac % 100 * 2);
    let out = &mut buf[pos..pos + 5];
    out[0] = b'.';
    out[1] = DIGIT_PAIRS[hi];
    out[2] = DIGIT_PAIRS[hi + 1];
    out[3] = DIGIT_PAIRS[lo];
    out[4] = DIGIT_PAIRS[lo + 1];
    pos + 5
}

/// Formats `v` the way every coordinate is written (tests and headers use it).
pub(crate) fn format_fixed4(v: f64) -> String {
    let mut b = [0u8; 32];
    let n = put_fixed4(&mut b, 0, quantize(v));
    String::from_utf8_lossy(&b[..n]).into_owned()
}

/// Streams atom lines of one dump into `out` through its own buffer.
pub(crate) struct Sink<'a, W: Write + ?Sized> {
    out: &'a mut W,
    /// Output buffer; `buf[..pos]` is pending.
    buf: Vec<u8>,
    pos: usize,
    pub(crate) bytes: u64,
    progress: &'a mut dyn FnMut(u64),
    /// Lines written in all frames so far.
    pub(crate) total_lines: u64,
    next_progress: u64,
    // Per frame:
    next_id: u64,
    /// `next_id` in decimal, left-aligned, kept in step by a text increment.
    id_text: [u8; 24],
    id_len: usize,
    /// Distinct (non-duplicate) particles allowed per frame; more are dropped silently.
    base_cap: u64,
    pub(crate) base_written: u64,
    dup_total: u64,
    dup_written: u64,
    /// Emit the next duplicate once `base_written` reaches this.
    next_dup_at: u64,
    /// Periodic lengths in x and y, quantized; positions are wrapped into `[0, len)`.
    wrap: [i64; 2],
    /// Raw arrays instead of text: positions go to `out` as little-endian f32 triples.
    binary: Option<BinaryOut<'a>>,
    /// Lines start with the type (XYZ) instead of the id and the type (LAMMPS).
    without_ids: bool,
}

/// The other arrays of a raw-array output: types (u8, 0-based) and the extra column
/// (f32), buffered.
pub(crate) struct BinaryOut<'a> {
    pub types: &'a mut dyn Write,
    pub extra: &'a mut dyn Write,
    tbuf: Vec<u8>,
    ebuf: Vec<u8>,
}

impl<'a> BinaryOut<'a> {
    pub(crate) fn new(types: &'a mut dyn Write, extra: &'a mut dyn Write) -> Self {
        BinaryOut {
            types,
            extra,
            tbuf: Vec::with_capacity(FLUSH_AT),
            ebuf: Vec::with_capacity(FLUSH_AT),
        }
    }
}

impl<'a, W: Write + ?Sized> Sink<'a, W> {
    pub(crate) fn new(out: &'a mut W, progress: &'a mut dyn FnMut(u64)) -> Self {
        Sink {
            out,
            buf: vec![0; FLUSH_AT + 2 * LINE_MAX],
            pos: 0,
            bytes: 0,
            progress,
            total_lines: 0,
            next_progress: PROGRESS_EVERY,
            next_id: 1,
            id_text: *b"1\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
            id_len: 1,
            base_cap: 0,
            base_written: 0,
            dup_total: 0,
            dup_written: 0,
            next_dup_at: u64::MAX,
            wrap: [i64::MAX; 2],
            binary: None,
            without_ids: false,
        }
    }

    /// Writes atom lines without ids from now on: `<type> x y z <extra>` (XYZ).
    pub(crate) fn set_without_ids(&mut self) {
        self.without_ids = true;
    }

    /// Starts a frame: `base` distinct particles, then `dups` extra lines repeating an
    /// earlier position, spread evenly; x and y wrap with the given periods.
    pub(crate) fn begin_frame(&mut self, base: u64, dups: u64, period: [f64; 2]) {
        self.next_id = 1;
        self.id_text[0] = b'1';
        self.id_len = 1;
        self.base_cap = base;
        self.base_written = 0;
        self.dup_total = dups;
        self.dup_written = 0;
        self.next_dup_at = self.dup_threshold(0);
        self.wrap = [quantize(period[0]), quantize(period[1])];
    }

    /// Base count after which duplicate number `k` (0-based) is written.
    fn dup_threshold(&self, k: u64) -> u64 {
        if k >= self.dup_total {
            return u64::MAX;
        }
        // ceil((k + 1) * base / dups)
        let num = (k as u128 + 1) * self.base_cap as u128;
        num.div_ceil(self.dup_total as u128) as u64
    }

    /// Writes raw arrays instead of text from now on.
    pub(crate) fn set_binary(&mut self, out: BinaryOut<'a>) {
        self.binary = Some(out);
    }

    pub(crate) fn raw(&mut self, text: &[u8]) -> io::Result<()> {
        if self.binary.is_some() {
            return Ok(());
        }
        if self.pos + text.len() > FLUSH_AT {
            self.flush_buf()?;
        }
        if text.len() > FLUSH_AT {
            self.out.write_all(text)?;
            self.bytes += text.len() as u64;
        } else {
            self.buf[self.pos..self.pos + text.len()].copy_from_slice(text);
            self.pos += text.len();
        }
        Ok(())
    }

    #[inline]
    fn maybe_flush(&mut self) -> io::Result<()> {
        if self.pos >= FLUSH_AT {
            self.flush_buf()?;
        }
        Ok(())
    }

    fn flush_buf(&mut self) -> io::Result<()> {
        if let Some(b) = self.binary.as_mut() {
            b.types.write_all(&b.tbuf)?;
            b.extra.write_all(&b.ebuf)?;
            b.tbuf.clear();
            b.ebuf.clear();
        }
        self.out.write_all(&self.buf[..self.pos])?;
        self.bytes += self.pos as u64;
        self.pos = 0;
        Ok(())
    }

    pub(crate) fn finish(&mut self) -> io::Result<()> {
        self.flush_buf()?;
        (self.progress)(self.total_lines);
        if let Some(b) = self.binary.as_mut() {
            b.types.flush()?;
            b.extra.flush()?;
        }
        self.out.flush()
    }

    /// Adds one to the decimal text of the id.
    #[inline]
    fn increment_id_text(&mut self) {
        let mut i = self.id_len;
        while i > 0 {
            i -= 1;
            if self.id_text[i] == b'9' {
                self.id_text[i] = b'0';
            } else {
                self.id_text[i] += 1;
                return;
            }
        }
        // All nines: 99 -> 100.
        self.id_text[0] = b'1';
        self.id_text[self.id_len] = b'0';
        self.id_len += 1;
    }

    #[inline]
    fn wrap_axis(q: i64, len: i64) -> i64 {
        if q >= len {
            q - len
        } else if q < 0 {
            q + len
        } else {
            q
        }
    }

    /// Writes one particle (and a duplicate of it when one is due).
    #[inline]
    pub(crate) fn atom(&mut self, ty: u32, p: [f64; 3], extra: f64) -> io::Result<()> {
        if self.base_written >= self.base_cap {
            return Ok(());
        }
        let q = [
            Self::wrap_axis(quantize(p[0]), self.wrap[0]),
            Self::wrap_axis(quantize(p[1]), self.wrap[1]),
            quantize(p[2]),
        ];
        let e = quantize(extra);
        self.line(ty, q, e);
        self.base_written += 1;
        while self.base_written == self.next_dup_at {
            self.line(ty, q, e);
            self.dup_written += 1;
            self.next_dup_at = self.dup_threshold(self.dup_written);
        }
        self.maybe_flush()
    }

    #[inline]
    fn line(&mut self, ty: u32, q: [i64; 3], e: i64) {
        if let Some(b) = self.binary.as_mut() {
            // The values the text would hold, as a reader parses them.
            for v in q {
                let x = (v as f64 / SCALE) as f32;
                self.buf[self.pos..self.pos + 4].copy_from_slice(&x.to_le_bytes());
                self.pos += 4;
            }
            b.tbuf.push(ty.saturating_sub(1).min(255) as u8);
            b.ebuf
                .extend_from_slice(&((e as f64 / SCALE) as f32).to_le_bytes());
            self.total_lines += 1;
            if self.total_lines >= self.next_progress {
                self.next_progress += PROGRESS_EVERY;
                (self.progress)(self.total_lines);
            }
            return;
        }
        let l = &mut self.buf[self.pos..self.pos + LINE_MAX];
        let mut n = if self.without_ids {
            put_u64(l, 0, ty as u64)
        } else {
            // Fixed-size copy (no call); the bytes past the id are overwritten below.
            l[..24].copy_from_slice(&self.id_text);
            let n = self.id_len;
            l[n] = b' ';
            put_u64(l, n + 1, ty as u64)
        };
        for v in [q[0], q[1], q[2], e] {
            l[n] = b' ';
            n = put_fixed4(l, n + 1, v);
        }
        l[n] = b'\n';
        self.pos += n + 1;
        self.next_id += 1;
        self.increment_id_text();
        self.total_lines += 1;
        if self.total_lines >= self.next_progress {
            self.next_progress += PROGRESS_EVERY;
            (self.progress)(self.total_lines);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed4_round_trips() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.00004,
            0.00005,
            -0.00005,
            3.615,
            1.8075,
            12345.67891,
            -987.65432,
            99.99995,
            1e9,
            -4.2e-7,
        ] {
            let s = format_fixed4(v);
            let back: f64 = s.parse().unwrap();
            assert!((back - v).abs() <= 0.5e-4 + 1e-12 * v.abs(), "{v} -> {s}");
            assert_eq!(s.split('.').nth(1).unwrap().len(), DECIMALS as usize, "{s}");
        }
        assert_eq!(format_fixed4(1.8075 * 7.0), "12.6525");
        assert_eq!(format_fixed4(-0.00004), "0.0000");
        assert_eq!(format_fixed4(-2.5), "-2.5000");
        assert_eq!(format_fixed4(100.0), "100.0000");
        assert_eq!(format_fixed4(999.99995), "1000.0000");
        assert_eq!(format_fixed4(-1234.56789), "-1234.5679");
        assert_eq!(format_fixed4(9999.99995), "10000.0000");
        assert_eq!(format_fixed4(123456.0001), "123456.0001");
        assert_eq!(format_fixed4(7.0), "7.0000");
        assert_eq!(format_fixed4(42.00005), "42.0001");
    }

    #[test]
    fn duplicates_spread_evenly_and_count_exactly() {
        for (base, dups) in [(10u64, 0u64), (10, 3), (7, 7), (1000, 1), (1000, 999)] {
            let mut out = Vec::new();
            let mut prog = |_| {};
            let mut s = Sink::new(&mut out, &mut prog);
            s.begin_frame(base, dups, [1e6, 1e6]);
            for i in 0..base + 5 {
                s.atom(1, [i as f64, 0.0, 0.0], 0.0).unwrap();
            }
            s.finish().unwrap();
            let text = String::from_utf8(out).unwrap();
            assert_eq!(text.lines().count() as u64, base + dups);
            let last = text.lines().last().unwrap();
            assert!(last.starts_with(&format!("{} ", base + dups)));
        }
    }
}
