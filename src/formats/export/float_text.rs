//! An f32 as `.usda` text, fast: the shorter of `{}` and `{:e}` (the exponent form keeps tiny
//! offsets such as `1.5e-9` from spelling out their leading zeros), the same bytes as std
//! formats, without std's formatting machinery.
//!
//! The digits are zmij's shortest round-trip digits (the formatter serde_json uses), which are
//! std's too except on an exact tie between two shortest candidates: zmij rounds half to even
//! (2110626.25 gives `2110626.2`), std rounds half up (`2110626.3`). A tie is recognised
//! exactly (the f32 is the midpoint of the digits and a neighbour) and left to std. Formatting
//! the digits through `write!` cost about 140 ns per float against about 40 ns this way: most
//! of a full-frame `.usda`'s time.

use std::fmt::Write;

/// The room [`f32_text`] needs: its text is at most 16 bytes (a sign, nine digits, a point and
/// `e-45`), and it writes in fixed blocks of 16 past it (fixed-size copies, not calls).
pub(crate) const ROOM: usize = 48;

/// Write `x` as `.usda` text at the start of `out` (at least [`ROOM`] bytes); its length.
pub(crate) fn f32_text(x: f32, out: &mut [u8]) -> usize {
    let out = &mut out[..ROOM];
    if !x.is_finite() {
        return std_text(x, out);
    }
    let mut zmij = zmij::Buffer::new();
    let text = zmij.format_finite(x).as_bytes();
    if is_plain_as_written(x, text) {
        out[..text.len()].copy_from_slice(text);
        return text.len();
    }
    let Some(Decimal { negative, significand, len, point }) = Decimal::parse(text) else {
        // Zero: `0` or `-0`.
        let text: &[u8] = if x.is_sign_negative() { b"-0" } else { b"0" };
        out[..text.len()].copy_from_slice(text);
        return text.len();
    };
    if is_tie(x, significand, point - len as i32) {
        return std_text(x, out);
    }
    // The digits, then zeros (what `{}` pads either side with).
    let mut digits = [b'0'; 32];
    let mut d = significand;
    for i in (0..len).rev() {
        digits[i] = b'0' + (d % 10) as u8;
        d /= 10;
    }
    let (n, p) = (len as i32, point);
    // `{}`: the digits with the point placed, padded with zeros either side.
    let plain = if p >= n {
        p
    } else if p > 0 {
        n + 1
    } else {
        2 - p + n
    };
    let exponent = p - 1;
    let exp = n + i32::from(n > 1) + 1 + i32::from(exponent < 0) + decimal_len(exponent.unsigned_abs());
    let at = usize::from(negative);
    out[0] = b'-';
    if exp < plain {
        // `D.DDDDe-X`: the digits after the first shifted right by one, the point between.
        out[at..at + 16].copy_from_slice(&digits[..16]);
        out[at + 2..at + 18].copy_from_slice(&digits[1..17]);
        out[at + 1] = b'.';
        let mut at = at + len + usize::from(len > 1);
        out[at] = b'e';
        out[at + 1] = b'-';
        at += 1 + usize::from(exponent < 0);
        at + put_decimal(exponent.unsigned_abs(), &mut out[at..])
    } else if p >= n {
        // Digits then zeros: the zeros are already there (`plain` is at most 16 long here).
        out[at..at + 16].copy_from_slice(&digits[..16]);
        at + p as usize
    } else if p > 0 {
        let p = p as usize;
        out[at..at + 16].copy_from_slice(&digits[..16]);
        out[at + p + 1..at + p + 17].copy_from_slice(&digits[p..p + 16]);
        out[at + p] = b'.';
        at + len + 1
    } else {
        let zeros = (-p) as usize;
        out[at..at + 16].fill(b'0');
        out[at + 1] = b'.';
        out[at + 2 + zeros..at + 2 + zeros + 16].copy_from_slice(&digits[..16]);
        at + 2 + zeros + len
    }
}

/// Whether zmij's `text` of `x` is already the text wanted, as it is for most coordinates: a
/// fraction (`I.F`, `F` not `0`, no exponent) is std's `{}` too, and shorter than `{:e}` unless
/// it starts `0.00` (`0.0012` and `1.2e-3` are as long; `0.001` is longer than `1e-3`). A
/// possible tie (the f32's last binary digit in the place below its last decimal one) is not.
#[inline]
fn is_plain_as_written(x: f32, text: &[u8]) -> bool {
    let body = &text[usize::from(x.is_sign_negative())..];
    let Some(dot) = body.iter().position(|&c| c == b'.') else {
        return false;
    };
    let fraction = &body[dot + 1..];
    if fraction == b"0" || fraction.contains(&b'e') {
        return false;
    }
    if body[0] == b'0' {
        let zeros = fraction.iter().take_while(|&&c| c == b'0').count();
        if zeros > 1 + usize::from(fraction.len() - zeros > 1) {
            return false;
        }
    }
    !may_tie(x, -(fraction.len() as i32))
}

/// The shorter of std's `{}` and `{:e}` (the reference the fast path keeps to).
fn std_text(x: f32, out: &mut [u8]) -> usize {
    let mut plain = String::new();
    let _ = write!(plain, "{x}");
    let exp = format!("{x:e}");
    let text = if exp.len() < plain.len() { exp } else { plain };
    out[..text.len()].copy_from_slice(text.as_bytes());
    text.len()
}

/// Shortest round-trip digits: the value is `0.SIGNIFICAND x 10^point`, the significand's
/// `len` digits neither beginning nor ending with zero.
struct Decimal {
    negative: bool,
    significand: u64,
    len: usize,
    point: i32,
}

impl Decimal {
    /// From zmij's text (`-12.5`, `0.001234`, `1.5e-7`, `1e+20`, `123456790.0`); `None` for
    /// zero.
    fn parse(text: &[u8]) -> Option<Decimal> {
        let negative = text[0] == b'-';
        let text = &text[usize::from(negative)..];
        // zmij writes `I.F` (`F` is `0` for an integer) or `M[.F]e[+-]X`.
        let (mantissa, exponent) = match text.iter().position(|&c| c == b'e') {
            Some(e) => (&text[..e], std::str::from_utf8(&text[e + 1..]).ok().and_then(|x| x.parse::<i32>().ok()).expect("zmij's exponent")),
            None => (text, 0),
        };
        let dot = mantissa.iter().position(|&c| c == b'.').unwrap_or(mantissa.len());
        let mut significand = 0u64;
        for &c in &mantissa[..dot] {
            significand = 10 * significand + u64::from(c - b'0');
        }
        let fraction = mantissa.get(dot + 1..).unwrap_or_default();
        for &c in fraction {
            significand = 10 * significand + u64::from(c - b'0');
        }
        if significand == 0 {
            return None;
        }
        // `0.000123`: the value is 0.123 x 10^-3; the digits are the significand's.
        let mut len = 1 + significand.ilog10() as usize;
        let point = if mantissa[0] == b'0' { exponent - (fraction.len() - len) as i32 } else { dot as i32 + exponent };
        // Zeros after the last significant digit count in the point's place, not as digits.
        while significand.is_multiple_of(10) {
            significand /= 10;
            len -= 1;
        }
        Some(Decimal { negative, significand, len, point })
    }
}

/// Whether `x` (finite, not zero) is exactly halfway between `d x 10^k` and a neighbour one
/// unit of the last digit away: where zmij's ties and std's differ. With `x = m 2^e`,
/// `m = odd 2^a`: `2x = (2d +- 1) 10^k` holds exactly when `a + e + 1 = k` and the odd parts
/// agree (`odd = (2d +- 1) 5^k`, or `odd 5^-k = 2d +- 1`).
fn is_tie(x: f32, d: u64, k: i32) -> bool {
    if !may_tie(x, k) {
        return false;
    }
    let (m, _) = binary(x);
    let a = m.trailing_zeros();
    let odd = u64::from(m >> a);
    let five = 5u64.pow(k.unsigned_abs());
    [2 * d + 1, 2 * d - 1].iter().any(|&half| if k >= 0 { odd == half * five } else { odd * five == half })
}

/// The first test of [`is_tie`]: `x`'s lowest binary digit is in the place `a + e` one below
/// `10^k`, the place of the last decimal digit (and `10^k` is small enough for the odd parts'
/// test).
#[inline]
fn may_tie(x: f32, k: i32) -> bool {
    let (m, e) = binary(x);
    m.trailing_zeros() as i32 + e + 1 == k && k.unsigned_abs() <= 13
}

/// `x` (finite, not zero) as `m 2^e`.
#[inline]
fn binary(x: f32) -> (u32, i32) {
    let bits = x.to_bits();
    let (biased, fraction) = ((bits >> 23) & 0xff, bits & 0x7f_ffff);
    if biased == 0 {
        (fraction, -149)
    } else {
        (fraction | 0x80_0000, biased as i32 - 150)
    }
}

fn decimal_len(x: u32) -> i32 {
    match x {
        0..=9 => 1,
        10..=99 => 2,
        _ => 3,
    }
}

/// `x` (under 1000) in decimal into `out`; its length.
fn put_decimal(x: u32, out: &mut [u8]) -> usize {
    let n = decimal_len(x) as usize;
    let mut x = x;
    for i in (0..n).rev() {
        out[i] = b'0' + (x % 10) as u8;
        x /= 10;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fast(x: f32) -> String {
        let mut b = [0; ROOM];
        let n = f32_text(x, &mut b);
        String::from_utf8(b[..n].to_vec()).unwrap()
    }

    fn reference(x: f32) -> String {
        let mut b = [0; ROOM];
        let n = std_text(x, &mut b);
        String::from_utf8(b[..n].to_vec()).unwrap()
    }

    /// The fast text is std's on the layouts' edges, on ties (where zmij's rounding differs),
    /// at every power of two's neighbours, on subnormals and on a sweep of bit patterns.
    #[test]
    fn the_text_is_stds() {
        let named = [
            0.0f32,
            -0.0,
            1.0,
            0.1,
            -2.5,
            1e-9,
            1.5e-7,
            123456790.0,
            1e20,
            0.001,
            1e-5,
            1e-4,
            12345.0,
            1e15,
            1e16,
            2_110_626.0 + 0.25,
            3.4e38,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            -f32::MIN_POSITIVE,
            0.3333333,
            100.0,
            1e7,
            1.234e-3,
            0.0625,
            1000.5,
            0.5,
            8388608.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        assert_eq!(fast(2_110_626.0 + 0.25), "2110626.3");
        let powers = (0..254u32).flat_map(|b| (0..8u32).map(move |d| (b << 23).wrapping_add(d).wrapping_sub(4)));
        let sweep = (0..1u64 << 32).step_by(65_537).map(|b| b as u32);
        let small = 1..1u32 << 16;
        for x in named.into_iter().chain(powers.chain(sweep).chain(small).map(f32::from_bits)) {
            assert_eq!(fast(x), reference(x), "{:#x}", x.to_bits());
        }
        // Ties: halves, quarters and eighths of integers, whose exact decimals are short.
        for i in 0..200_000u32 {
            for x in [i as f32 + 0.5, i as f32 * 8.0 + 0.25, (i * 1024) as f32 + 0.125, i as f32 * 0.0625] {
                assert_eq!(fast(x), reference(x), "{x}");
                assert_eq!(fast(-x), reference(-x), "{x}");
            }
        }
    }

    /// Every finite f32 (4,278,190,080 bit patterns) against std's text, on the pool: about 25
    /// CPU minutes, so run by hand (`-- --ignored`) after a change to this module.
    #[test]
    #[ignore]
    fn every_finite_f32_is_stds() {
        use rayon::prelude::*;
        let mismatches: u64 = (0..1u32 << 16)
            .into_par_iter()
            .map(|high| {
                let bits = (high << 16)..=(high << 16 | 0xffff);
                let (mut a, mut b) = ([0; ROOM], [0; ROOM]);
                let mut differs = |x: f32| {
                    let (n, m) = (f32_text(x, &mut a), std_text(x, &mut b));
                    a[..n] != b[..m]
                };
                bits.map(f32::from_bits).filter(|x| x.is_finite()).filter(|&x| differs(x)).count() as u64
            })
            .sum();
        assert_eq!(mismatches, 0);
    }
}
