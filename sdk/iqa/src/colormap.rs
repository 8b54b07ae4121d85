//! The error maps' colour map: perceptually ordered, dark to light.
//!
//! Lightness rises linearly in Oklab (L from 0.15 to 0.97) while the hue
//! turns from violet through red and orange to pale yellow, so equal steps
//! of error look like equal steps of brightness and the map stays readable
//! in grey. Pixels with no value (NaN/Inf in an input) are cyan, a colour
//! the map never reaches.

/// Colour of pixels that have no error value.
pub const NO_VALUE: [u8; 3] = [0, 255, 255];

/// Steps of the table [`color`] reads.
const TABLE_STEPS: usize = 4096;

/// The colour of `t` in [0, 1] (clamped) as 8-bit sRGB, from a table of
/// 4097 colours (`t` to the nearest 1/4096): an error map colours millions
/// of pixels, and [`exact_color`] costs a sine, a cosine and four powers.
/// Table and formula differ by at most one 8-bit level.
pub fn color(t: f32) -> [u8; 3] {
    static TABLE: std::sync::OnceLock<Vec<[u8; 3]>> = std::sync::OnceLock::new();
    if t.is_nan() {
        return NO_VALUE;
    }
    let table = TABLE.get_or_init(|| (0..=TABLE_STEPS).map(|i| exact_color(i as f32 / TABLE_STEPS as f32)).collect());
    // `+ 0.5` then truncation rounds (the value is not negative), without a call to `round`.
    table[(t.clamp(0.0, 1.0) * TABLE_STEPS as f32 + 0.5) as usize]
}

/// The colour of `t` in [0, 1] (clamped) as 8-bit sRGB, by the formula.
pub fn exact_color(t: f32) -> [u8; 3] {
    if t.is_nan() {
        return NO_VALUE;
    }
    let t = t.clamp(0.0, 1.0) as f64;
    let l = 0.15 + 0.82 * t;
    // Chroma peaks mid-way and fades at both ends; hue turns 300° → 100°.
    let chroma = 0.16 * (std::f64::consts::PI * t).sin().powf(0.8) + 0.02;
    let hue = (300.0 + 160.0 * t).to_radians();
    let (a, b) = (chroma * hue.cos(), chroma * hue.sin());
    oklab_to_srgb8(l, a, b)
}

/// Oklab (Ottosson 2020) to 8-bit sRGB, out-of-gamut values clamped.
fn oklab_to_srgb8(l: f64, a: f64, b: f64) -> [u8; 3] {
    let l_ = l + 0.396_337_777_4 * a + 0.215_803_757_3 * b;
    let m_ = l - 0.105_561_345_8 * a - 0.063_854_172_8 * b;
    let s_ = l - 0.089_484_177_5 * a - 1.291_485_548 * b;
    let (l3, m3, s3) = (l_ * l_ * l_, m_ * m_ * m_, s_ * s_ * s_);
    let rgb = [
        4.076_741_662_1 * l3 - 3.307_711_591_3 * m3 + 0.230_969_929_2 * s3,
        -1.268_438_004_6 * l3 + 2.609_757_401_1 * m3 - 0.341_319_396_5 * s3,
        -0.004_196_086_3 * l3 - 0.703_418_614_7 * m3 + 1.707_614_701 * s3,
    ];
    rgb.map(|v| (crate::image::srgb(v as f32) * 255.0 + 0.5) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luma(c: [u8; 3]) -> f64 {
        0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
    }

    #[test]
    fn brightness_rises_monotonically() {
        let mut last = -1.0;
        for i in 0..=64 {
            let y = luma(color(i as f32 / 64.0));
            assert!(y > last, "step {i}: {y} after {last}");
            last = y;
        }
        assert!(luma(color(0.0)) < 30.0 && luma(color(1.0)) > 220.0);
    }

    #[test]
    fn the_table_is_within_one_level_of_the_formula() {
        for i in 0..=100_000 {
            let t = i as f32 / 100_000.0;
            let (table, exact) = (color(t), exact_color(t));
            for c in 0..3 {
                assert!(table[c].abs_diff(exact[c]) <= 1, "t = {t}: table {table:?}, formula {exact:?}");
            }
        }
    }

    #[test]
    fn out_of_range_clamps_and_nan_is_marked() {
        assert_eq!(color(-3.0), color(0.0));
        assert_eq!(color(7.0), color(1.0));
        assert_eq!(color(f32::NAN), NO_VALUE);
    }
}
