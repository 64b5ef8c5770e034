//! A ray as the walk reads it: its steps across the grid's columns and rows, and its tests
//! against height ranges, bands and boxes.

use glam::{Vec3A, Vec4};

use super::{Band, GridRay, HeightFieldAccel, Range, MAX_BAND_SLOPE};

impl<const FUSED: bool> GridRay<FUSED> {
    #[inline(always)]
    pub(super) fn new(accel: &HeightFieldAccel, origin: Vec3A, direction: Vec3A) -> GridRay<FUSED> {
        // A zero component gets a tiny one instead, so that slab distances stay finite and
        // ordered (a ray along a slab's plane is inside it).
        let tiny = Vec3A::splat(1e-30);
        let inv = Vec3A::select(direction.abs().cmplt(tiny), tiny, direction).recip();
        let (g, e) = (&accel.grid, accel.slack);
        let mut ray = GridRay {
            origin,
            direction,
            inv,
            x_step: accel.step.0 * inv.x,
            x_start: (g.xs[0] - origin.x) * inv.x,
            y_step: accel.step.1 * inv.y,
            y_start: (g.ys[0] - origin.y) * inv.y,
            margin: e * max(inv.x.abs(), inv.y.abs()),
            reach: {
                let (x_width, y_width) =
                    ((accel.step.0 * inv.x).abs(), (accel.step.1 * inv.y).abs());
                let (x_graze, y_graze) = (2.0 * e * inv.x.abs(), 2.0 * e * inv.y.abs());
                Vec4::new(x_width - x_graze, y_width - y_graze, x_graze, y_graze)
            },
            forward_x: accel.step.0 * inv.x > 0.0,
            forward_y: accel.step.1 * inv.y > 0.0,
            t_near: f32::NAN,
            t_far: f32::NAN,
            z_slack: 0.0,
        };
        if let Some((near, far)) = ray.box_span(accel.field_box) {
            ray.t_near = near;
            ray.t_far = far * (1.0 + 8.0 * f32::EPSILON);
            // |z − a·x − b·y| at a point within t_far: the point's rounding (2 ulps of its
            // largest coordinate, times 1 + |a| + |b|) and the expression's own (3 ulps).
            let reach = origin.abs().max_element() + ray.t_far;
            ray.z_slack = (5.0 * (1.0 + 2.0 * MAX_BAND_SLOPE as f32) + 8.0) * f32::EPSILON * reach;
        }
        ray
    }

    /// `a·b + c`, fused with `FUSED`.
    #[inline(always)]
    fn madd(a: f32, b: f32, c: f32) -> f32 {
        if FUSED {
            a.mul_add(b, c)
        } else {
            a * b + c
        }
    }

    /// Distances at which the ray meets the line of vertex column `col` and of vertex row
    /// `row`.
    #[inline(always)]
    pub(super) fn boundaries(&self, row: i32, col: i32) -> (f32, f32) {
        (
            Self::madd(col as f32, self.x_step, self.x_start),
            Self::madd(row as f32, self.y_step, self.y_start),
        )
    }

    /// Distances at which the ray leaves cell (`row`, `col`) of `level` through its x side
    /// and its y side, and the distance it leaves the cell (not before `t_in`).
    #[inline(always)]
    pub(super) fn exits(&self, level: usize, row: i32, col: i32, t_in: f32) -> (f32, f32, f32) {
        let (tx, ty) = self.boundaries(
            (row + i32::from(self.forward_y)) << level,
            (col + i32::from(self.forward_x)) << level,
        );
        (tx, ty, max(min(tx, ty), t_in))
    }

    /// Whether the ray's stretch [`t_in`, `t_out`] may meet heights in `range`.
    #[inline(always)]
    pub(super) fn meets(&self, range: Range, (t_in, t_out): (f32, f32)) -> bool {
        self.meets_linear(
            self.origin.z,
            self.direction.z,
            (t_in, t_out),
            (range.min, range.max),
        )
    }

    /// Distances at which the ray enters (0 if it starts inside) and leaves the box with
    /// corners `lo` and `hi`, if it meets it.
    #[inline(always)]
    fn box_span(&self, (lo, hi): (Vec3A, Vec3A)) -> Option<(f32, f32)> {
        if lo.z > hi.z {
            return None;
        }
        let (lo, hi) = ((lo - self.origin) * self.inv, (hi - self.origin) * self.inv);
        let near = lo.min(hi).max_element().max(0.0);
        let far = lo.max(hi).min_element();
        (near <= far * (1.0 + 4.0 * f32::EPSILON)).then_some((near, far))
    }

    /// Whether the ray's stretch [`t_in`, `t_out`] may meet `band` (it does not when it passes
    /// above or below it at both ends).
    #[inline(always)]
    pub(super) fn meets_band(&self, band: Band, t_in: f32, t_out: f32) -> bool {
        // z − a·x − b·y along the ray is linear in t.
        let (o, d) = (self.origin, self.direction);
        let h0 = Self::madd(-band.b, o.y, Self::madd(-band.a, o.x, o.z));
        let dh = Self::madd(-band.b, d.y, Self::madd(-band.a, d.x, d.z));
        self.meets_linear(h0, dh, (t_in, t_out), (band.c_lo, band.c_hi))
    }

    /// Whether `h0 + dh·t` may lie in [`lo`, `hi`] for some t of [`t_in`, `t_out`] (cut at
    /// `t_far`), allowing for rounding: it does not when it is above or below at both ends.
    #[inline(always)]
    fn meets_linear(
        &self,
        h0: f32,
        dh: f32,
        (t_in, t_out): (f32, f32),
        (lo, hi): (f32, f32),
    ) -> bool {
        let t_out = min(t_out, self.t_far);
        let (hp, hq) = (Self::madd(dh, t_in, h0), Self::madd(dh, t_out, h0));
        let above = min(hp, hq) - self.z_slack > hi;
        let below = max(hp, hq) + self.z_slack < lo;
        !(above || below)
    }
}

/// Asks for the cache line holding `value` (a hint: no effect on results).
#[inline(always)]
pub(super) fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching a valid reference's address has no effect but on the caches.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (value as *const T).cast(),
        );
    }
}

/// The smaller of `a` and `b` (`b` when unordered): one instruction, unlike `f32::min`.
#[inline(always)]
pub(super) fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The larger of `a` and `b` (`b` when unordered).
#[inline(always)]
pub(super) fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}
