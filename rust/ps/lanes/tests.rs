//! Tests of the lanes of each instruction set.

use super::*;

/// `pattern` repeated over `W` lanes.
fn lanes<T: Copy, const W: usize>(pattern: [T; 8]) -> [T; W] {
    std::array::from_fn(|lane| pattern[lane % 8])
}

/// Every operation of `isa` on values that cover signs, zeros and the largest integer.
fn check<V: Isa<W>, const W: usize>(isa: V) {
    let a = isa.floats(lanes([1.0, -2.0, 3.0, -4.0, 0.5, 6.0, -0.0, 8.0]));
    let b = isa.splat(2.0);
    assert_eq!(
        (a + b).to_array(),
        lanes([3.0, 0.0, 5.0, -2.0, 2.5, 8.0, 2.0, 10.0])
    );
    assert_eq!((a - b).to_array()[3], -6.0);
    assert_eq!((a * b).to_array()[5], 12.0);
    assert_eq!((a * 0.5).to_array()[W - 1], 4.0);
    assert_eq!(
        (a / b).to_array(),
        lanes([0.5, -1.0, 1.5, -2.0, 0.25, 3.0, -0.0, 4.0])
    );
    assert_eq!(
        a.max(isa.splat(0.0)).to_array(),
        lanes([1.0, 0.0, 3.0, 0.0, 0.5, 6.0, 0.0, 8.0])
    );
    let mut sum = a;
    sum += b;
    assert_eq!(sum.to_array()[0], 3.0);
    let near_one = isa.splat(1.0 + f32::EPSILON * 2048.0);
    let fused = near_one.mul_add(near_one, isa.splat(-(1.0 + f32::EPSILON * 4096.0)));
    assert_eq!(
        fused.to_array(),
        [f32::EPSILON / 2.0; W],
        "a multiply-add rounds once (twice would give 0)"
    );
    let nan = isa.splat_int(i32::MAX).to_floats();
    for mask in [
        nan.simd_lt(a),
        nan.simd_gt(a),
        a.simd_lt(nan),
        (nan * 0.0).simd_lt(a),
    ] {
        assert_eq!(
            mask.to_bits().to_array(),
            [0; W],
            "no comparison with a NaN holds"
        );
    }
    assert_eq!(
        nan.max(b).to_array(),
        [2.0; W],
        "the maximum of a NaN and a number is the number"
    );
    assert!(
        b.max(nan).to_array().iter().all(|v| v.is_nan()),
        "a NaN second is kept"
    );
    assert_eq!(
        a.simd_lt(b).to_bits().to_array(),
        lanes([-1, -1, 0, -1, -1, 0, -1, 0])
    );
    assert_eq!(
        (a & a.simd_gt(b)).to_array(),
        lanes([0.0, 0.0, 3.0, 0.0, 0.0, 6.0, 0.0, 8.0])
    );
    assert_eq!(
        (a ^ isa.splat(-0.0)).to_array(),
        lanes([-1.0, 2.0, -3.0, 4.0, -0.5, -6.0, 0.0, -8.0])
    );
    assert_eq!(a.to_bits().to_floats().to_array(), a.to_array());
    let i = isa.ints(lanes([5, -1, i32::MAX, 0, 7, 7, -8, 2]));
    let j = isa.splat_int(2);
    assert_eq!(i.simd_lt(j).to_array(), lanes([0, -1, 0, -1, 0, 0, -1, 0]));
    assert_eq!(((i + j) - j).to_array()[2], i32::MAX, "integers wrap");
    assert_eq!((i + j).to_array()[2], i32::MIN + 1, "integers wrap");
    assert_eq!(i.simd_eq(j).to_array(), lanes([0, 0, 0, 0, 0, 0, 0, -1]));
    assert_eq!(
        i.halved().to_array(),
        lanes([2, -1, i32::MAX / 2, 0, 3, 3, -4, 1])
    );
    assert_eq!(i.min(j).to_array(), lanes([2, -1, 2, 0, 2, 2, -8, 2]));
    assert_eq!(i.max(j).to_array(), lanes([5, 2, i32::MAX, 2, 7, 7, 2, 2]));
    let mut count = isa.splat_int(0);
    count -= i.simd_lt(j);
    assert_eq!(count.to_array(), lanes([0, 1, 0, 1, 0, 0, 1, 0]));
    assert_eq!((i + j).to_array()[6], -6);
    assert_eq!((i & j).to_array()[2], 2);
    assert_eq!(
        (i ^ j).to_array(),
        lanes([7, -3, i32::MAX ^ 2, 2, 5, 5, -6, 0])
    );
}

#[test]
fn portable_lanes_act_on_each_value_and_compare_to_masks() {
    check(Portable);
}

#[cfg(target_arch = "x86_64")]
#[test]
fn avx2_lanes_act_on_each_value_and_compare_to_masks() {
    if let Some(avx2) = Avx2::detect() {
        check(avx2);
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn avx512_lanes_act_on_each_value_and_compare_to_masks() {
    if let Some(avx512) = Avx512::detect() {
        check(avx512);
    }
}
