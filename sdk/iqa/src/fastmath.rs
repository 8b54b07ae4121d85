//! Cube root, base-2 logarithm and power in f32 from polynomials and bit
//! manipulation: within a few ulps of the library's, and, unlike a call to
//! `powf` per value, they vectorise in the pixel loops that use them (ꟻLIP's
//! colour conversions, error-map scales).

/// The cube root of `t` ≥ 0.008 (CIELab's cube branch), within an ulp or two
/// of `powf(t, 1/3)`: a guess from the exponent bits, refined by a Halley
/// and a Newton step. Unlike a call to the library's `powf`, it vectorises.
#[inline(always)]
pub(crate) fn cbrt(t: f32) -> f32 {
    // Dividing the bit pattern by 3 (in f32, exact enough for a guess) divides the exponent by 3.
    let third = t.to_bits() as i32 as f32 * (1.0 / 3.0);
    // SAFETY: `third` is finite and below 2³¹ (a third of a positive float's bits);
    // the checked cast would saturate lane by lane and not vectorise.
    let guess = unsafe { third.to_int_unchecked::<i32>() };
    let mut y = f32::from_bits((guess + 0x2A51_4067) as u32);
    // A Halley step (it cubes the error, a few per cent, to about 1e−5),
    // then a Newton step (it squares it, and rounds well): two divisions
    // where three Newton steps would need three.
    let y3 = y * y * y;
    y = y * (y3 + 2.0 * t) / (2.0 * y3 + t);
    (2.0 * y + t / (y * y)) * (1.0 / 3.0)
}

/// `log₂ x` for finite `x` > 0, within about 1e−7 (absolute) of the exact
/// value: exponent and mantissa m in [√½, √2); ln m = 2 atanh(s),
/// s = (m − 1)/(m + 1), |s| ≤ 0.172, by its series to s⁹. 0 gives −150.
#[inline(always)]
pub(crate) fn log2(x: f32) -> f32 {
    let tiny = x < f32::MIN_POSITIVE;
    let scaled = if tiny { x * 8_388_608.0 } else { x };
    let bits = scaled.to_bits();
    let mantissa = f32::from_bits((bits & 0x007F_FFFF) | 0x3F80_0000);
    let high = mantissa > std::f32::consts::SQRT_2;
    let m = if high { mantissa * 0.5 } else { mantissa };
    let exponent = ((bits >> 23) & 0xFF) as i32 - 127 + high as i32 - if tiny { 23 } else { 0 };
    let sv = (m - 1.0) / (m + 1.0);
    let s2 = sv * sv;
    let ln_m = sv * (2.0 + s2 * (2.0 / 3.0 + s2 * (2.0 / 5.0 + s2 * (2.0 / 7.0 + s2 * (2.0 / 9.0)))));
    exponent as f32 + ln_m * std::f32::consts::LOG2_E
}

/// `x^y` for `x` ≥ 0 and finite `y`, within a few ulps of `powf` (`0^0` is
/// 1), as `2^(y · log₂ x)` from polynomials that vectorise, where the
/// library's `powf` is a call per value.
#[inline(always)]
pub(crate) fn pow(x: f32, y: f32) -> f32 {
    let log2 = log2(x);
    // 2^z: z = n + f, |f| ≤ ½, 2^f by its series to the 7th power; 2^n in two halves so that
    // results down to the subnormals come out right.
    let z = (y * log2).clamp(-200.0, 127.9);
    // Rounding by adding 1.5 · 2²³: the sum's low mantissa bits are the integer (no saturating cast).
    const ROUND: f32 = 12_582_912.0;
    let shifted = z + ROUND;
    let n = shifted - ROUND;
    let t = (z - n) * std::f32::consts::LN_2;
    let p = 1.0
        + t * (1.0
            + t * (1.0 / 2.0
                + t * (1.0 / 6.0 + t * (1.0 / 24.0 + t * (1.0 / 120.0 + t * (1.0 / 720.0 + t * (1.0 / 5040.0)))))));
    let n = shifted.to_bits() as i32 - ROUND.to_bits() as i32;
    let (n1, n2) = (n >> 1, n - (n >> 1));
    let two_to = |k: i32| f32::from_bits(((k + 127) as u32) << 23);
    let v = p * two_to(n1) * two_to(n2);
    if x == 0.0 {
        if y > 0.0 {
            0.0
        } else if y == 0.0 {
            1.0
        } else {
            f32::INFINITY
        }
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_root_is_within_two_ulps_of_powf() {
        let mut t = 0.008f32;
        while t < 2.0 {
            let (ours, theirs) = (cbrt(t), t.powf(1.0 / 3.0));
            assert!((ours - theirs).abs() <= 2.0 * f32::EPSILON * theirs, "cbrt({t}) = {ours}, powf gives {theirs}");
            t = t * 1.0001 + 1e-7;
        }
    }

    #[test]
    fn pow_is_within_a_few_ulps_of_powf() {
        let mut x = 1e-42f32;
        while x < 300.0 {
            for y in [0.0f32, 0.05, 0.3, 0.5, 0.7, 0.999, 1.0, 1.3, -0.2] {
                let (ours, theirs) = (pow(x, y), x.powf(y));
                // The rounding of y · log₂ x grows with its size: an ulp of the result per unit.
                let allowed = 4.0 + (y * x.log2()).abs();
                let ulps = (ours - theirs).abs() / (theirs * f32::EPSILON).max(f32::from_bits(1));
                assert!(ulps <= allowed, "pow({x}, {y}) = {ours}, powf gives {theirs}");
            }
            x *= 1.37;
        }
        assert_eq!((pow(0.0, 0.7), pow(0.0, 0.0), pow(0.0, -1.0)), (0.0, 1.0, f32::INFINITY));
    }

    #[test]
    fn log2_is_within_1e7_of_the_exact_value() {
        let mut x = 1e-42f32;
        while x < 1e30 {
            assert!(
                (log2(x) as f64 - (x as f64).log2()).abs() < 1e-6 * (1.0 + (x as f64).log2().abs() / 16.0),
                "log2({x})"
            );
            x *= 1.37;
        }
    }
}
