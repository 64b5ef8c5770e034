//! Discontinuity-preserving normal integration, for orthographic and perspective cameras.
//!
//! The surface is found at the mask's pixels from their normals alone. Each pixel's normal
//! gives the slope of the unknown between the pixel and each of its four neighbours: of the
//! height (in pixel units) for an orthographic camera, of the logarithm of the depth along
//! the optical axis for a pinhole camera, where the slope equations stay linear. Every
//! slope equation is written without a division, `t (z_q − z_p) + a = 0` (`t` and `a` from
//! the normal and the pixel's ray), so a grazing normal weakens its equations instead of
//! blowing them up.
//!
//! A pixel next to a depth discontinuity (an occluding contour) agrees with its neighbour
//! on one side and not on the other. As in bilateral normal integration (Cao et al., ECCV
//! 2022), each pixel weighs its two one-sided equations along each axis by how well each
//! side agrees with it: the side whose difference `t Δ` is the larger gets the weight
//! `σ(k (Δ_other² − Δ_this²))` (σ the logistic function), and the weights and the surface
//! are found in turn (iteratively re-weighted least squares) from the plain least-squares
//! surface, until the weighted energy changes by less than a relative tolerance. `t Δ` is
//! in pixel footprints for both cameras, so `k` does not depend on the object's size or
//! distance.
//!
//! Each step solves the weighted graph Laplacian of the mask's 4-neighbours exactly with a
//! sparse Cholesky factor whose symbolic analysis is done once. A part of the surface that
//! the weights cut off from the rest has an offset that its normals do not fix: a tiny
//! proximal term (`PROXIMAL`, relative to each pixel's stiffness) keeps it where the step
//! before left it, and makes every system positive definite.

use crate::error::{Error, Result};
use crate::integrate::sparse_cholesky::{Factorisation, SparseCholesky};
use crate::memory::try_vec;

/// Weight, relative to each pixel's own stiffness, of the pull toward the previous
/// solution: numerically nothing for an offset that the equations determine, and the
/// offset's only anchor where they do not.
const PROXIMAL: f64 = 1e-8;

/// The camera whose pixels the normals were seen through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Parallel rays along −z: the unknown is the height, in pixel units.
    Orthographic,
    /// A pinhole with focal lengths and principal point in pixels (contract §1b: pixel
    /// (i, j) is centred at image point (j + ½, i + ½)): the unknown is the logarithm of
    /// the depth along the optical axis.
    Perspective { fx: f64, fy: f64, cx: f64, cy: f64 },
}

/// Settings of [`integrate_bilateral`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BilateralSettings {
    /// Sharpness `k` of the one-sided weights, per squared pixel footprint.
    pub sharpness: f64,
    /// Most re-weighted solves.
    pub max_iterations: usize,
    /// The iterations stop when the weighted energy changes by less than this fraction.
    pub tolerance: f64,
}

impl Default for BilateralSettings {
    fn default() -> Self {
        BilateralSettings {
            sharpness: 2.0,
            max_iterations: 150,
            tolerance: 1e-4,
        }
    }
}

/// What [`integrate_bilateral`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct BilateralSurface {
    /// Row-major (height × width): the log depth (perspective) or the height in pixel units
    /// (orthographic) at each mask pixel, up to one constant per connected part; NaN
    /// outside the mask.
    pub values: Vec<f64>,
    /// Row-major: bit [`CUT_RIGHT`] where the edge to the right neighbour is a
    /// discontinuity, bit [`CUT_DOWN`] where the edge to the pixel below is one (both
    /// pixels in the mask, the edge keeping less than half the weight of a smooth one).
    pub cuts: Vec<u8>,
    /// Re-weighted solves done.
    pub iterations: usize,
    /// Whether the energy settled within the tolerance before `max_iterations`.
    pub converged: bool,
}

/// Bit of [`BilateralSurface::cuts`]: the edge to the right neighbour is cut.
pub const CUT_RIGHT: u8 = 1;
/// Bit of [`BilateralSurface::cuts`]: the edge to the pixel below is cut.
pub const CUT_DOWN: u8 = 2;

/// One slope equation's coefficients at a pixel: `t Δ + a = 0`.
#[derive(Debug, Clone, Copy)]
struct Slope {
    t: f64,
    a: f64,
}

/// An edge between two 4-neighbours of the mask (`low` before `high` in row-major order),
/// with the slots of its off-diagonal entry in the matrix.
#[derive(Debug, Clone, Copy)]
struct Edge {
    low: usize,
    high: usize,
    /// 0 for a horizontal edge (along u), 1 for a vertical one (along v).
    axis: usize,
    slot: usize,
}

/// The mask's graph, its matrix pattern (upper triangle, compressed columns) and the
/// equations' coefficients.
struct System {
    /// Per unknown, its pixel (row-major).
    pixels: Vec<usize>,
    edges: Vec<Edge>,
    diagonal_slot: Vec<usize>,
    indptr: Vec<usize>,
    indices: Vec<usize>,
    /// Per unknown, per axis (u, v).
    slopes: Vec<[Slope; 2]>,
}

/// Integrates the unit normals at the mask's pixels into a surface that keeps its depth
/// discontinuities (see the module's documentation).
///
/// `normals` is row-major (height × width × 3) in the contract's frame (x right, y up, z
/// toward the camera), read only inside `mask` (height × width), where they must be
/// finite.
pub fn integrate_bilateral(
    normals: &[f32],
    mask: &[bool],
    height: usize,
    width: usize,
    projection: Projection,
    settings: BilateralSettings,
) -> Result<BilateralSurface> {
    check_inputs(normals, mask, height, width, projection, settings)?;
    let (index, count) = unknowns(mask)?;
    let mut cuts = try_vec("cuts", height * width, 0u8)?;
    let mut values = try_vec("values", height * width, f64::NAN)?;
    if count == 0 {
        return Ok(BilateralSurface {
            values,
            cuts,
            iterations: 0,
            converged: true,
        });
    }
    let system = build_system(normals, mask, &index, height, width, count, projection)?;
    // Per edge, the weights of the low pixel's forward and the high pixel's backward equation.
    let mut weights = try_vec("weights", 2 * system.edges.len(), 0.5f64)?;
    let mut z = try_vec("unknowns", count, 0.0f64)?;
    let mut data = try_vec("matrix", system.indices.len(), 0.0f64)?;
    let mut rhs = try_vec("right-hand side", count, 0.0f64)?;
    let mut factor: Option<SparseCholesky> = None;
    // The energy of a flat surface: below a tiny fraction of it, a change is rounding.
    let flat_energy = weighted_energy(&system, &weights, &z);
    let mut energy_before: Option<f64> = None;
    let (mut iterations, mut converged) = (0, false);
    while iterations < settings.max_iterations {
        assemble(&system, &weights, &z, &mut data, &mut rhs);
        match factor.as_mut() {
            None => {
                factor = Some(SparseCholesky::factor_with(
                    "integration",
                    count,
                    &system.indptr,
                    &system.indices,
                    &data,
                    Factorisation::Supernodal,
                )?)
            }
            Some(factor) => {
                factor.refactor("integration", &system.indptr, &system.indices, &data)?
            }
        }
        factor
            .as_ref()
            .expect("factored above")
            .solve_in_place("integration", &mut rhs, 1)?;
        z.copy_from_slice(&rhs);
        iterations += 1;
        reweight(&system, &z, count, settings.sharpness, &mut weights)?;
        let energy = weighted_energy(&system, &weights, &z);
        if let Some(before) = energy_before {
            if (energy - before).abs() <= settings.tolerance * before.max(1e-12 * flat_energy) {
                converged = true;
                break;
            }
        }
        energy_before = Some(energy);
    }
    for (&pixel, &value) in system.pixels.iter().zip(&z) {
        values[pixel] = value;
    }
    for (edge, pair) in system.edges.iter().zip(weights.chunks_exact(2)) {
        if pair[0] + pair[1] < 0.5 {
            let pixel = system.pixels[edge.low];
            cuts[pixel] |= if edge.axis == 0 { CUT_RIGHT } else { CUT_DOWN };
        }
    }
    Ok(BilateralSurface {
        values,
        cuts,
        iterations,
        converged,
    })
}

fn check_inputs(
    normals: &[f32],
    mask: &[bool],
    height: usize,
    width: usize,
    projection: Projection,
    settings: BilateralSettings,
) -> Result<()> {
    let pixels = height
        .checked_mul(width)
        .ok_or_else(|| Error::input("mask", format!("{height}x{width} pixels overflow")))?;
    if mask.len() != pixels {
        return Err(Error::input(
            "mask",
            format!("{} values for {height}x{width} pixels", mask.len()),
        ));
    }
    if normals.len() != pixels * 3 {
        return Err(Error::input(
            "normals",
            format!("{} values for {height}x{width}x3", normals.len()),
        ));
    }
    if let Some(pixel) =
        (0..pixels).find(|&p| mask[p] && normals[3 * p..3 * p + 3].iter().any(|v| !v.is_finite()))
    {
        return Err(Error::input(
            "normals",
            format!(
                "non-finite normal at row {}, column {}",
                pixel / width,
                pixel % width
            ),
        ));
    }
    if let Projection::Perspective { fx, fy, cx, cy } = projection {
        if !(fx.is_finite() && fx > 0.0 && fy.is_finite() && fy > 0.0) {
            return Err(Error::input(
                "intrinsics",
                format!("focal lengths must be positive and finite, got fx {fx}, fy {fy}"),
            ));
        }
        if !(cx.is_finite() && cy.is_finite()) {
            return Err(Error::input(
                "intrinsics",
                format!("principal point must be finite, got ({cx}, {cy})"),
            ));
        }
    }
    if !(settings.sharpness.is_finite() && settings.sharpness > 0.0) {
        return Err(Error::input(
            "sharpness",
            format!("must be positive and finite, got {}", settings.sharpness),
        ));
    }
    if !(settings.tolerance.is_finite() && settings.tolerance >= 0.0) {
        return Err(Error::input(
            "tolerance",
            format!(
                "must be finite and not negative, got {}",
                settings.tolerance
            ),
        ));
    }
    Ok(())
}

/// Each pixel's unknown (`usize::MAX` outside the mask) in row-major order, and their count.
fn unknowns(mask: &[bool]) -> Result<(Vec<usize>, usize)> {
    let mut index = try_vec("unknowns' index", mask.len(), usize::MAX)?;
    let mut count = 0;
    for (slot, &inside) in index.iter_mut().zip(mask) {
        if inside {
            *slot = count;
            count += 1;
        }
    }
    Ok((index, count))
}

/// The slope equations' coefficients of a pixel's normal (contract frame) along u
/// (columns) and v (rows).
fn slopes(normal: [f64; 3], row: usize, column: usize, projection: Projection) -> [Slope; 2] {
    let [nx, ny, nz] = normal;
    match projection {
        // Height z(x, y) with x along the columns and y against the rows:
        // ∂z/∂column = −nx/nz and ∂z/∂row = ny/nz.
        Projection::Orthographic => [Slope { t: nz, a: nx }, Slope { t: nz, a: -ny }],
        // In the camera frame (x right, y down, z forward) the normal is (nx, −ny, −nz)
        // and the pixel's ray r = ((u − cx)/fx, (v − cy)/fy, 1); the surface point d·r is
        // tangent to the normal along u and v, which gives
        // fx (n·r) ∂ln d/∂u + n_x = 0 and fy (n·r) ∂ln d/∂v + n_y = 0.
        Projection::Perspective { fx, fy, cx, cy } => {
            let (u, v) = (column as f64 + 0.5, row as f64 + 0.5);
            let along_ray = nx * (u - cx) / fx - ny * (v - cy) / fy - nz;
            [
                Slope {
                    t: fx * along_ray,
                    a: nx,
                },
                Slope {
                    t: fy * along_ray,
                    a: -ny,
                },
            ]
        }
    }
}

fn build_system(
    normals: &[f32],
    mask: &[bool],
    index: &[usize],
    height: usize,
    width: usize,
    count: usize,
    projection: Projection,
) -> Result<System> {
    let mut slope_table = Vec::new();
    slope_table
        .try_reserve_exact(count)
        .map_err(|_| Error::memory("slopes", count * std::mem::size_of::<[Slope; 2]>()))?;
    let mut edges = Vec::new();
    edges
        .try_reserve_exact(2 * count)
        .map_err(|_| Error::memory("edges", 2 * count * std::mem::size_of::<Edge>()))?;
    let mut indptr = try_vec("matrix columns", count + 1, 0usize)?;
    let mut indices = Vec::new();
    indices
        .try_reserve_exact(3 * count)
        .map_err(|_| Error::memory("matrix pattern", 3 * count * std::mem::size_of::<usize>()))?;
    let mut diagonal_slot = try_vec("matrix diagonal", count, 0usize)?;
    let mut pixels = try_vec("pixels", count, 0usize)?;
    for row in 0..height {
        for column in 0..width {
            let pixel = row * width + column;
            if !mask[pixel] {
                continue;
            }
            let unknown = index[pixel];
            pixels[unknown] = pixel;
            let n = &normals[3 * pixel..3 * pixel + 3];
            slope_table.push(slopes(
                [f64::from(n[0]), f64::from(n[1]), f64::from(n[2])],
                row,
                column,
                projection,
            ));
            // Column `unknown` of the upper triangle: the pixel above, the one to the left
            // (both earlier in row-major order), then the diagonal.
            if row > 0 && mask[pixel - width] {
                edges.push(Edge {
                    low: index[pixel - width],
                    high: unknown,
                    axis: 1,
                    slot: indices.len(),
                });
                indices.push(index[pixel - width]);
            }
            if column > 0 && mask[pixel - 1] {
                edges.push(Edge {
                    low: index[pixel - 1],
                    high: unknown,
                    axis: 0,
                    slot: indices.len(),
                });
                indices.push(index[pixel - 1]);
            }
            diagonal_slot[unknown] = indices.len();
            indices.push(unknown);
            indptr[unknown + 1] = indices.len();
        }
    }
    Ok(System {
        pixels,
        edges,
        diagonal_slot,
        indptr,
        indices,
        slopes: slope_table,
    })
}

/// The normal equations of the weighted energy, with the proximal pull toward `previous`.
fn assemble(system: &System, weights: &[f64], previous: &[f64], data: &mut [f64], rhs: &mut [f64]) {
    data.fill(0.0);
    rhs.fill(0.0);
    for (edge, pair) in system.edges.iter().zip(weights.chunks_exact(2)) {
        let ends = [
            system.slopes[edge.low][edge.axis],
            system.slopes[edge.high][edge.axis],
        ];
        for (slope, &weight) in ends.iter().zip(pair) {
            // weight · (t (z_high − z_low) + a)²
            let stiffness = weight * slope.t * slope.t;
            let pull = weight * slope.t * slope.a;
            data[edge.slot] -= stiffness;
            data[system.diagonal_slot[edge.low]] += stiffness;
            data[system.diagonal_slot[edge.high]] += stiffness;
            rhs[edge.high] -= pull;
            rhs[edge.low] += pull;
        }
    }
    let mean_diagonal =
        system.diagonal_slot.iter().map(|&s| data[s]).sum::<f64>() / previous.len() as f64;
    let floor = if mean_diagonal > 0.0 {
        mean_diagonal
    } else {
        1.0
    };
    for (unknown, &slot) in system.diagonal_slot.iter().enumerate() {
        let own = data[slot];
        let proximal = PROXIMAL * if own > 0.0 { own } else { floor };
        data[slot] += proximal;
        rhs[unknown] += proximal * previous[unknown];
    }
}

/// The one-sided weights of every pixel from the surface `z`: along each axis, the side
/// whose difference `t Δ` is the larger gets `σ(k (Δ_other² − Δ_this²))`, the other the rest.
fn reweight(
    system: &System,
    z: &[f64],
    count: usize,
    sharpness: f64,
    weights: &mut [f64],
) -> Result<()> {
    // Per unknown, per axis: the squared weighted differences to the next and the previous
    // neighbour (0 where there is none).
    let mut forward = try_vec("differences", 2 * count, 0.0f64)?;
    let mut backward = try_vec("differences", 2 * count, 0.0f64)?;
    for edge in &system.edges {
        let step = z[edge.high] - z[edge.low];
        let low = system.slopes[edge.low][edge.axis].t * step;
        let high = system.slopes[edge.high][edge.axis].t * step;
        forward[2 * edge.low + edge.axis] = low * low;
        backward[2 * edge.high + edge.axis] = high * high;
    }
    for (edge, pair) in system.edges.iter().zip(weights.chunks_exact_mut(2)) {
        let low = 2 * edge.low + edge.axis;
        let high = 2 * edge.high + edge.axis;
        // The low pixel's forward equation, and the high pixel's backward one.
        pair[0] = logistic(sharpness * (backward[low] - forward[low]));
        pair[1] = logistic(sharpness * (forward[high] - backward[high]));
    }
    Ok(())
}

fn logistic(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// Σ weight · (t Δ + a)² over every equation.
fn weighted_energy(system: &System, weights: &[f64], z: &[f64]) -> f64 {
    system
        .edges
        .iter()
        .zip(weights.chunks_exact(2))
        .map(|(edge, pair)| {
            let step = z[edge.high] - z[edge.low];
            let low = system.slopes[edge.low][edge.axis];
            let high = system.slopes[edge.high][edge.axis];
            pair[0] * (low.t * step + low.a).powi(2) + pair[1] * (high.t * step + high.a).powi(2)
        })
        .sum()
}

#[cfg(test)]
mod tests;
