//! PNG images of 8 or 16 bits, values normalised to [0, 1] by `2^bits - 1`.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

use crate::error::{Error, Result};
use crate::memory::{try_collect, try_vec};

use super::{check_data_len, check_size, Image};

/// How many bytes of decoded PNG pixels one byte of file can hold at most: deflate expands
/// at most 1032 times, and expanding a 1-bit palette image to 8-bit RGBA 32 times more.
const PNG_MAX_EXPANSION: u64 = 1032 * 32;

/// Reads an 8- or 16-bit PNG (gray, gray+alpha, RGB, RGBA or palette), alpha dropped,
/// values divided by `2^bits - 1`. Returns the image and its bit depth.
pub fn read_png(path: &Path) -> Result<(Image, u8)> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| Error::format(path, format!("not a readable PNG file ({e})")))?;
    let (width, height) = reader.info().size();
    check_size(path, width as usize, height as usize)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Error::format(path, "PNG dimensions are too large"))?;
    if size as u64 > file_len.saturating_mul(PNG_MAX_EXPANSION) {
        return Err(Error::format(
            path,
            format!("corrupt PNG: its header claims {width}x{height} pixels, more than its {file_len} bytes can hold"),
        ));
    }
    let mut buffer = try_vec(
        &format!("{}: its decoded {width}x{height} pixels", path.display()),
        size,
        0u8,
    )?;
    let info = reader
        .next_frame(&mut buffer)
        .map_err(|e| Error::format(path, format!("corrupt PNG data ({e})")))?;
    let (width, height) = (info.width as usize, info.height as usize);
    let (bits, scale) = match info.bit_depth {
        png::BitDepth::Sixteen => (16u8, 65535.0f32),
        _ => (8u8, 255.0f32),
    };
    let in_channels = info.color_type.samples();
    let keep = if in_channels >= 3 { 3 } else { 1 };
    let bytes = &buffer[..info.buffer_size()];
    let sample = |i: usize| -> f32 {
        if bits == 16 {
            u16::from_be_bytes([bytes[2 * i], bytes[2 * i + 1]]) as f32 / scale
        } else {
            bytes[i] as f32 / scale
        }
    };
    let values = (0..width * height)
        .flat_map(|p| (0..keep).map(move |c| p * in_channels + c))
        .map(sample);
    let data = try_collect(
        &format!("{}: its {width}x{height} pixels as float32", path.display()),
        width * height * keep,
        values,
    )?;
    Ok((
        Image {
            width,
            height,
            channels: keep,
            data,
        },
        bits,
    ))
}

/// Writes an image of values in [0, 1] (clipped) as an 8- or 16-bit gray or RGB PNG.
///
/// A NaN or an infinity is refused (naming its row and column): it has no PNG value.
pub fn write_png(path: &Path, image: &Image, bit_depth: u8) -> Result<()> {
    check_data_len(image)?;
    if let Some(index) = image.data.iter().position(|v| !v.is_finite()) {
        let pixel = index / image.channels;
        let (row, column) = (pixel / image.width, pixel % image.width);
        return Err(Error::input(
            "image",
            format!(
                "non-finite value {} at row {row}, column {column}",
                image.data[index]
            ),
        ));
    }
    let color = match image.channels {
        1 => png::ColorType::Grayscale,
        3 => png::ColorType::Rgb,
        n => {
            return Err(Error::input(
                "image",
                format!("{n} channels: PNG output takes 1 or 3"),
            ))
        }
    };
    let what = format!(
        "{}: the {}x{} pixels to write",
        path.display(),
        image.width,
        image.height
    );
    let (depth, bytes): (png::BitDepth, Vec<u8>) = match bit_depth {
        8 => (
            png::BitDepth::Eight,
            try_collect(
                &what,
                image.data.len(),
                image
                    .data
                    .iter()
                    .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8),
            )?,
        ),
        16 => {
            let bytes = image
                .data
                .iter()
                .flat_map(|&v| ((v.clamp(0.0, 1.0) * 65535.0).round() as u16).to_be_bytes());
            (
                png::BitDepth::Sixteen,
                try_collect(&what, 2 * image.data.len(), bytes)?,
            )
        }
        b => {
            return Err(Error::input(
                "bit_depth",
                format!("{b}: PNG output takes 8 or 16"),
            ))
        }
    };
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    let mut encoder = png::Encoder::new(
        BufWriter::new(file),
        image.width as u32,
        image.height as u32,
    );
    encoder.set_color(color);
    encoder.set_depth(depth);
    let mut writer = encoder.write_header().map_err(|e| Error::io(path, e))?;
    writer
        .write_image_data(&bytes)
        .map_err(|e| Error::io(path, e))?;
    writer.finish().map_err(|e| Error::io(path, e))
}
