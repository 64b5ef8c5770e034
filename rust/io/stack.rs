//! Images read by their extension, and stacks of them read in parallel.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::try_vec;

use super::exr_image::read_exr;
use super::png_image::read_png;
use super::Image;

/// Reads one image by its extension (`.exr` or `.png`), as RGB.
pub fn read_image_rgb(path: &Path) -> Result<Image> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let image = match ext.as_deref() {
        Some("exr") => read_exr(path)?,
        Some("png") => read_png(path)?.0,
        _ => {
            return Err(Error::format(
                path,
                "unknown image type: expected .exr or .png",
            ))
        }
    };
    image.into_rgb()
}

/// Reads a stack of images in parallel into one `(K, H, W, 3)` buffer.
///
/// Every image must have the size of the first and only finite values; the error names
/// the first file that does not. Each image is decoded straight into its slot of the
/// result, so the peak memory is the result plus one decoded image per thread.
pub fn read_image_stack(paths: &[PathBuf]) -> Result<(usize, usize, Vec<f32>)> {
    let Some(first_path) = paths.first() else {
        return Err(Error::input("paths", "no images given"));
    };
    let first = read_image_rgb(first_path)?;
    let (width, height) = (first.width, first.height);
    let plane = width * height * 3;
    let what = format!(
        "the {} images of {width}x{height} as float32 RGB",
        paths.len()
    );
    let mut data = try_vec(&what, paths.len().saturating_mul(plane), 0.0f32)?;
    data[..plane].copy_from_slice(&first.data);
    drop(first);
    data.par_chunks_mut(plane)
        .zip(paths)
        .skip(1)
        .try_for_each(|(slot, path)| -> Result<()> {
            let image = read_image_rgb(path)?;
            if (image.width, image.height) != (width, height) {
                return Err(Error::format(
                    path,
                    format!(
                        "size {}x{} differs from {} ({}x{})",
                        image.width,
                        image.height,
                        first_path.display(),
                        width,
                        height
                    ),
                ));
            }
            slot.copy_from_slice(&image.data);
            Ok(())
        })?;
    for (path, slot) in paths.iter().zip(data.chunks(plane)) {
        if let Some(index) = slot.iter().position(|v| !v.is_finite()) {
            let pixel = index / 3;
            return Err(Error::format(
                path,
                format!(
                    "non-finite value {} at row {}, column {}",
                    slot[index],
                    pixel / width,
                    pixel % width
                ),
            ));
        }
    }
    Ok((width, height, data))
}
