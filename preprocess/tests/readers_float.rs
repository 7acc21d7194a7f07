//! `parse_f64` must agree with `str::parse::<f64>` bit for bit, and fail exactly where it
//! fails.

use mdlod_preprocess::readers::parse_f64;

fn check(s: &str) {
    let want = s.parse::<f64>().ok().map(f64::to_bits);
    let got = parse_f64(s.as_bytes()).map(f64::to_bits);
    assert_eq!(got, want, "`{s}`: got {got:?}, str::parse gives {want:?}");
}

/// xorshift64*: deterministic and dependency-free.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn f64_bits(&mut self) -> f64 {
        f64::from_bits(self.next())
    }
}

#[test]
fn special_forms() {
    for s in [
        "0",
        "-0",
        "+0",
        "0.0",
        "-0.0",
        "00000",
        "1",
        "-1",
        "+1",
        "1.",
        ".5",
        "-.5",
        "+.5",
        "1.e5",
        ".e5",
        "e5",
        ".",
        "-",
        "+",
        "",
        " 1",
        "1 ",
        "1e",
        "1e+",
        "1e-",
        "1e+5",
        "1E5",
        "1e-5",
        "1.5e308",
        "1e309",
        "-1e309",
        "1e-400",
        "4.9e-324",
        "2.2250738585072014e-308",
        "nan",
        "NaN",
        "-nan",
        "inf",
        "-inf",
        "+inf",
        "Infinity",
        "infinity",
        "INF",
        "1d5",
        "1.0D+00",
        "0x10",
        "1_000",
        "1,5",
        "--1",
        "+-1",
        "1..2",
        "1.2.3",
        "1e5.5",
        "١",
        "9007199254740992",
        "9007199254740993",
        "9007199254740993.0",
        "1e22",
        "1e23",
        "123456789012345678",
        "1234567890123456789",
        "12345678901234567890",
        "0.000000000000000000000000000001",
        "100000000000000000000000",
        "3.141592653589793238462643383279",
        "1e-22",
        "1e-23",
        "0e999999",
        "1e-99999",
        "1e99999",
        "0.1",
        "0.2",
        "0.3",
        "2.5",
        "-12.3456",
        "1.23456e-05",
        "6.02214076e23",
    ] {
        check(s);
    }
}

#[test]
fn random_decimal_strings() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut s = String::new();
    for _ in 0..300_000 {
        s.clear();
        match rng.below(3) {
            0 => s.push('-'),
            1 if rng.below(4) == 0 => s.push('+'),
            _ => {}
        }
        for _ in 0..rng.below(12) {
            s.push(char::from(b'0' + rng.below(10) as u8));
        }
        if rng.below(4) != 0 {
            s.push('.');
            for _ in 0..rng.below(20) {
                s.push(char::from(b'0' + rng.below(10) as u8));
            }
        }
        if rng.below(3) == 0 {
            s.push(if rng.below(2) == 0 { 'e' } else { 'E' });
            match rng.below(3) {
                0 => s.push('-'),
                1 => s.push('+'),
                _ => {}
            }
            for _ in 0..rng.below(4) {
                s.push(char::from(b'0' + rng.below(10) as u8));
            }
        }
        check(&s);
    }
}

#[test]
fn formatted_doubles_round_trip() {
    let mut rng = Rng(12345);
    for i in 0..200_000 {
        let v = match i % 3 {
            0 => rng.f64_bits(),
            1 => {
                (rng.next() as f64 / u64::MAX as f64 - 0.5) * 10f64.powi(rng.below(20) as i32 - 10)
            }
            _ => (rng.below(2_000_000) as f64 - 1e6) / 1000.0,
        };
        if !v.is_finite() {
            continue;
        }
        check(&format!("{v}"));
        check(&format!("{v:e}"));
        check(&format!("{v:.6}"));
        check(&format!("{v:.5e}"));
        check(&format!("{v:.16e}"));
        check(&format!("{:.3}", v as f32));
    }
}
