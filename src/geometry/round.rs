//! f64 to f32 rounded one known way, for bounds that must stay bounds.

/// The greatest f32 at most `x` (f32's largest for finite numbers beyond
/// it; NaN for NaN). A plain conversion rounds to the nearest f32, up as
/// often as down, and among f32's subnormals (below 2^-126) those lie
/// 2^-149 apart whatever `x`: no margin in proportion to `x` taken off
/// first covers that.
pub fn f32_at_most(x: f64) -> f32 {
    let nearest = x as f32;
    if f64::from(nearest) > x {
        nearest.next_down()
    } else {
        nearest
    }
}

/// The least f32 at least `x` (see [`f32_at_most`]).
pub fn f32_at_least(x: f64) -> f32 {
    -f32_at_most(-x)
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        /// At any scale, subnormal and past f32's range included, each
        /// rounding lands on x's side and the next f32 beyond it does not.
        #[test]
        fn each_rounding_is_the_nearest_f32_on_its_side_of_x(
            mantissa in 0.5f64..1.0,
            exponent in -160i32..140,
            negative: bool,
        ) {
            let x = mantissa * 2f64.powi(exponent) * if negative { -1.0 } else { 1.0 };
            let (below, above) = (f32_at_most(x), f32_at_least(x));
            proptest::prop_assert!(f64::from(below) <= x, "{} > {}", below, x);
            proptest::prop_assert!(f64::from(above) >= x, "{} < {}", above, x);
            if below < f32::MAX {
                proptest::prop_assert!(f64::from(below.next_up()) > x, "{} ≤ {}", below.next_up(), x);
            }
            if above > f32::MIN {
                proptest::prop_assert!(f64::from(above.next_down()) < x, "{} ≥ {}", above.next_down(), x);
            }
        }
    }
}
