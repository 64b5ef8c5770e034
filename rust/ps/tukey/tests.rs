//! Tests of the Tukey fit: its medians, and the same bits in every instruction set.

use glam::{Mat3, Vec3};

use crate::ps::kernel::PixelFit;
use crate::ps::lanes::Isa;

use super::median::median_keys;
use super::*;

#[test]
fn median_keys_match_a_sort_for_ties_gaps_and_guesses_on_either_side() {
    check_median_keys(Portable);
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
        check_median_keys(avx2);
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(avx512) = crate::ps::lanes::Avx512::detect() {
        check_median_keys(avx512);
    }
}

/// The registers a test runs the fit in.
#[derive(Debug, Clone, Copy)]
enum Registers {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

/// The registers of this CPU besides [`Registers::Portable`].
fn wider_registers() -> Vec<Registers> {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = crate::ps::lanes::Avx2::detect().map(|_| Registers::Avx2);
        let avx512 = crate::ps::lanes::Avx512::detect().map(|_| Registers::Avx512);
        avx2.into_iter().chain(avx512).collect()
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec::new()
}

/// A pixel's true normal and albedo.
type Truth = (Vec3, f32);

/// The fits of `pixels` pixels of random normals and albedos under `count` lights, with
/// soft shadows, highlights and saturated observations among them, in `registers`, and
/// each pixel's true normal and albedo.
fn fits_of_noisy_pixels(
    pixels: usize,
    count: usize,
    registers: Registers,
) -> (Vec<(usize, PixelFit)>, Vec<Truth>) {
    let mut state = 99u32;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    };
    let directions: Vec<Vec3> = (0..count)
        .map(|k| {
            Vec3::new(
                (k as f32 * 2.4).cos(),
                (k as f32 * 2.4).sin(),
                1.0 + k as f32 / 20.0,
            )
            .normalize()
        })
        .collect();
    let gram = directions
        .iter()
        .fold(Mat3::ZERO, |m, &l| m + crate::ps::kernel::outer(l));
    let lights = Lights::new(
        &directions,
        &vec![[1.0; 3]; count],
        &vec![[1.5; 3]; count],
        gram,
    );
    let mut images = vec![0.0f32; count * pixels * 3];
    let mut truth = Vec::with_capacity(pixels);
    for p in 0..pixels {
        let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0).normalize();
        let albedo = 0.2 + 0.6 * uniform();
        truth.push((normal, albedo));
        for (k, l) in directions.iter().enumerate() {
            let mut value = albedo * l.dot(normal).max(0.0);
            match (uniform() * 10.0) as u32 {
                0 => value *= 0.3 * uniform(),
                1 => value += 0.8 * uniform(),
                _ => value *= 1.0 + 0.01 * (uniform() - 0.5),
            }
            images[(k * pixels + p) * 3..][..3].fill(value);
        }
    }
    let mask = vec![true; pixels];
    let pixels: Vec<usize> = (0..pixels).collect();
    let source = Source {
        images: &images,
        n: mask.len(),
        lights: &lights,
        shadow_fraction: 0.05,
    };
    let mut fits = Vec::new();
    match registers {
        Registers::Portable => {
            Machine::<8>::new(&lights).run_in(Portable, Portable, &source, &pixels, &mut fits)
        }
        // SAFETY: `wider_registers` found the instructions.
        #[cfg(target_arch = "x86_64")]
        Registers::Avx2 => unsafe {
            Machine::new(&lights).run_avx2(
                crate::ps::lanes::Avx2::detect().expect("AVX2"),
                &source,
                &pixels,
                &mut fits,
            )
        },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        Registers::Avx512 => unsafe {
            Machine::new(&lights).run_avx512(
                crate::ps::lanes::Avx512::detect().expect("AVX-512"),
                &source,
                &pixels,
                &mut fits,
            )
        },
    }
    (fits, truth)
}

#[test]
fn the_fit_finds_the_true_normals_and_albedos_with_the_same_bits_in_every_instruction_set() {
    // 37: lights that fill no whole lane group and an odd one out in the pairwise sums.
    for count in [40, 37] {
        let (portable, truth) = fits_of_noisy_pixels(300, count, Registers::Portable);
        assert_eq!(portable.len(), 300);
        let (mut angle_deg, mut albedo_error) = (0.0, 0.0);
        for (pixel, fit) in &portable {
            let (normal, albedo) = truth[*pixel];
            angle_deg += Vec3::from(fit.normal)
                .dot(normal)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
                / 300.0;
            albedo_error += fit.albedo.iter().map(|a| (a - albedo).abs()).sum::<f32>() / 900.0;
        }
        assert!(
            angle_deg < 0.5 && albedo_error < 0.005,
            "{count} lights: mean error {angle_deg}°, albedo {albedo_error}"
        );
        // Sixteen lanes finish the pixels in another order: compare them pixel by pixel.
        let by_pixel = |mut fits: Vec<(usize, PixelFit)>| {
            fits.sort_by_key(|&(pixel, _)| pixel);
            fits
        };
        let portable = by_pixel(portable);
        for registers in wider_registers() {
            assert_eq!(
                by_pixel(fits_of_noisy_pixels(300, count, registers).0),
                portable,
                "{count} lights, {registers:?}"
            );
        }
    }
}

fn check_median_keys<V: Isa<W>, const W: usize>(isa: V) {
    let mut state = 12345u32;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    };
    for trial in 0..200 {
        let k_count = 4 + (next() % 93) as usize;
        let mut keys = vec![[UNLIT; W]; k_count];
        for key in keys.iter_mut() {
            for lane in key.iter_mut() {
                let roll = next() % 10;
                *lane = match roll {
                    0 => UNLIT,
                    1 => 0x3c00_0000, // ties
                    _ => {
                        (next() % 0x4000_0000) as i32 + if trial % 2 == 0 { 0x3000_0000 } else { 0 }
                    }
                };
            }
        }
        let lit: [i32; W] =
            std::array::from_fn(|lane| keys.iter().filter(|k| k[lane] != UNLIT).count() as i32);
        let guess: [i32; W] = std::array::from_fn(|lane| {
            [0, 0x3c00_0000, 0x3400_0000, 0x7000_0000][(lane + trial) % 4]
        });
        let active: [bool; W] = std::array::from_fn(|lane| lit[lane] > 0);
        let bracket: [i32; W] =
            std::array::from_fn(|lane| [BRACKET, BRACKET_MIN, 1 << 16][(lane + trial) % 3]);
        let median = median_keys(isa, &keys, lit, guess, bracket, active);
        for lane in (0..W).filter(|&lane| active[lane]) {
            let mut sorted: Vec<i32> = keys
                .iter()
                .map(|k| k[lane])
                .filter(|&k| k != UNLIT)
                .collect();
            sorted.sort_unstable();
            assert_eq!(
                median[lane],
                sorted[lit[lane] as usize / 2],
                "trial {trial} lane {lane}"
            );
        }
    }
}
