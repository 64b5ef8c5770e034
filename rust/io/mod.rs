//! Reading and writing images: OpenEXR (float R, G, B or Y, [`exr_image`]) and PNG (8 or
//! 16 bit, [`png_image`]); images read by their extension, and stacks of them in parallel
//! ([`stack`]).
//!
//! Pixel data is row-major, top row first, channels interleaved, as `f32`.
//! PNG values are normalised to [0, 1] by `2^bits - 1` (linear, per the scene contract).

use std::path::Path;

use crate::error::{Error, Result};
use crate::memory::try_collect;

pub mod exr_image;
pub mod png_image;
pub mod stack;

/// The largest image the readers accept, in pixels (2^27: e.g. 16384 x 8192). A header
/// claiming more is rejected before any pixel memory is allocated.
pub const MAX_IMAGE_PIXELS: usize = 1 << 27;

/// An image in memory: `height` rows of `width` pixels of `channels` interleaved `f32` values.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Image {
    /// The same image with a single channel replicated to three (RGB unchanged), or
    /// [`Error::Memory`] when the copy cannot be allocated.
    pub fn into_rgb(self) -> Result<Image> {
        if self.channels == 3 {
            return Ok(self);
        }
        let what = format!("an RGB copy of a {}x{} image", self.width, self.height);
        let data = try_collect(
            &what,
            3 * self.data.len(),
            self.data.iter().flat_map(|&v| [v, v, v]),
        )?;
        Ok(Image {
            channels: 3,
            data,
            ..self
        })
    }
}

/// Rejects an image size with no pixel or more than `MAX_IMAGE_PIXELS`.
fn check_size(path: &Path, width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::format(
            path,
            format!("size {width}x{height} has no pixel"),
        ));
    }
    if width.saturating_mul(height) > MAX_IMAGE_PIXELS {
        return Err(Error::format(
            path,
            format!("size {width}x{height} exceeds the largest supported image ({MAX_IMAGE_PIXELS} pixels)"),
        ));
    }
    Ok(())
}

/// Refuses an image of no pixel, or whose data are not `width` × `height` × `channels`
/// values.
fn check_data_len(image: &Image) -> Result<()> {
    if image.width == 0 || image.height == 0 {
        return Err(Error::input(
            "image",
            format!("size {}x{} has no pixel", image.width, image.height),
        ));
    }
    if image.data.len() != image.width * image.height * image.channels {
        return Err(Error::input(
            "image",
            "data length does not match width x height x channels",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
