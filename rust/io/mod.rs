//! Reading and writing images: OpenEXR (float R, G, B or Y) and PNG (8 or 16 bit).
//!
//! Pixel data is row-major, top row first, channels interleaved, as `f32`.
//! PNG values are normalised to [0, 1] by `2^bits - 1` (linear, per the scene contract).
//! An EXR image is its display window: its data window's pixels are placed where that
//! window lies in it, the display window's pixels outside the data window are 0 and data
//! outside the display window is not read.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

use exr::prelude::*;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::{check_available, try_collect, try_vec};

/// The largest image the readers accept, in pixels (2^27: e.g. 16384 x 8192). A header
/// claiming more is rejected before any pixel memory is allocated.
pub const MAX_IMAGE_PIXELS: usize = 1 << 27;

/// How many bytes of decoded PNG pixels one byte of file can hold at most: deflate expands
/// at most 1032 times, and expanding a 1-bit palette image to 8-bit RGBA 32 times more.
const PNG_MAX_EXPANSION: u64 = 1032 * 32;

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

/// Reads an OpenEXR file with channels R, G, B (3 channels) or Y (1 channel): the pixels of
/// its display window (see the module's documentation for the data window).
pub fn read_exr(path: &Path) -> Result<Image> {
    if !path.is_file() {
        return Err(Error::io(path, "no such file"));
    }
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::format(path, format!("not a readable OpenEXR file ({e})")))?;
    for header in &meta.headers {
        check_size(path, header.layer_size.width(), header.layer_size.height())?;
        let display = header.shared_attributes.display_window.size;
        check_size(path, display.width(), display.height())?;
    }
    check_decoding_memory(path, &meta)?;
    // On the calling thread: the parallel decoder builds a thread pool for each file (with
    // its threads' stacks and allocator arenas, which an address-space limit counts and
    // whose failure aborts), and the stack of a data set is decoded in parallel by file.
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_file(path)
        .map_err(|e| Error::format(path, format!("not a readable OpenEXR file ({e})")))?;
    let display = image.attributes.display_window;
    let layer = image.layer_data;
    let data_window = IntegerBounds::new(layer.attributes.layer_position, layer.size);
    let channels = &layer.channel_data.list;
    let find = |name: &str| channels.iter().find(|c| c.name.eq(name));
    let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
    let rgb = find("R").is_some() && find("G").is_some() && find("B").is_some();
    let extra_alpha = usize::from(find("A").is_some());
    let wanted: Vec<&str> = if rgb && names.len() == 3 + extra_alpha {
        vec!["R", "G", "B"]
    } else if find("Y").is_some() && names.len() == 1 {
        vec!["Y"]
    } else {
        return Err(Error::format(
            path,
            format!("channels {names:?}: expected R, G, B (optionally A) or a single Y"),
        ));
    };
    let planes: Vec<&FlatSamples> = wanted
        .iter()
        .map(|n| &find(n).expect("channel checked above").sample_data)
        .collect();
    if planes.iter().any(|p| p.len() != data_window.size.area()) {
        return Err(Error::format(
            path,
            "channels are subsampled; only full-resolution channels are supported",
        ));
    }
    into_display_window(path, &planes, data_window, display)
}

/// Refuses, with [`Error::Memory`], a file whose decoding the memory left cannot hold: the
/// EXR decoder allocates its layers' samples (at most 4 bytes each) without a way to fail,
/// and the image of the display window is made beside them.
fn check_decoding_memory(path: &Path, meta: &exr::meta::MetaData) -> Result<()> {
    let samples: usize = meta
        .headers
        .iter()
        .map(|h| h.layer_size.area().saturating_mul(h.channels.list.len()))
        .fold(0, usize::saturating_add);
    let Some(first) = meta.headers.first() else {
        return Ok(());
    };
    let display = first.shared_attributes.display_window.size;
    let bytes = samples
        .saturating_add(display.area().saturating_mul(3))
        .saturating_mul(4);
    let what = format!(
        "{}: decoding its {}x{} data window",
        path.display(),
        first.layer_size.width(),
        first.layer_size.height()
    );
    check_available(&what, bytes)
}

/// The image of the display window `display` whose pixels inside `data_window` are those
/// of `planes` (one per channel, the data window's pixels row by row), interleaved; 0
/// elsewhere.
fn into_display_window(
    path: &Path,
    planes: &[&FlatSamples],
    data_window: IntegerBounds,
    display: IntegerBounds,
) -> Result<Image> {
    let (width, height, n) = (display.size.width(), display.size.height(), planes.len());
    let what = format!(
        "{}: the pixels of its {width}x{height} display window",
        path.display()
    );
    let mut data = try_vec(&what, width * height * n, 0.0f32)?;
    let data_width = data_window.size.width();
    // Where the data window's rows and columns fall in the display window (i64: the
    // windows may lie anywhere in i32 space).
    let offset = |data: i32, display: i32| i64::from(data) - i64::from(display);
    let (dx, dy) = (
        offset(data_window.position.x(), display.position.x()),
        offset(data_window.position.y(), display.position.y()),
    );
    let inside = |offset: i64, data_len: usize, display_len: usize| {
        (
            offset.max(0),
            (offset + data_len as i64).min(display_len as i64),
        )
    };
    let ((x0, x1), (y0, y1)) = (
        inside(dx, data_width, width),
        inside(dy, data_window.size.height(), height),
    );
    for (c, plane) in planes.iter().enumerate() {
        for y in y0..y1 {
            for x in x0..x1 {
                let source = (y - dy) as usize * data_width + (x - dx) as usize;
                data[(y as usize * width + x as usize) * n + c] =
                    plane.value_by_flat_index(source).to_f32();
            }
        }
    }
    Ok(Image {
        width,
        height,
        channels: n,
        data,
    })
}

/// Writes a 1-channel (Y) or 3-channel (R, G, B) image as 32-bit float OpenEXR, zip-compressed.
pub fn write_exr(path: &Path, image: &Image) -> Result<()> {
    let names: &[&str] = match image.channels {
        1 => &["Y"],
        3 => &["R", "G", "B"],
        n => {
            return Err(Error::input(
                "image",
                format!("{n} channels: EXR output takes 1 or 3"),
            ))
        }
    };
    check_data_len(image)?;
    let n = image.channels;
    let what = format!(
        "{}: a channel of {}x{} pixels to write",
        path.display(),
        image.width,
        image.height
    );
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (c, name) in names.iter().enumerate() {
        let plane = try_collect(
            &what,
            image.width * image.height,
            image.data.iter().skip(c).step_by(n).copied(),
        )?;
        list.push(AnyChannel::new(*name, FlatSamples::F32(plane)));
    }
    let mut layer = Layer::new(
        (image.width, image.height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    layer.encoding.compression = Compression::ZIP16;
    // On the calling thread, as the files are read (see `read_exr`): one block of 16 rows
    // at a time, whose copies (the rows, their bytes regrouped, the compressed bytes and
    // the compressor's state) the encoder allocates without a way to fail.
    let block = image.width.saturating_mul(n).saturating_mul(16 * 4);
    check_available(
        &format!("{}: the OpenEXR encoder's buffers", path.display()),
        block.saturating_mul(4).saturating_add(1 << 20),
    )?;
    Image2::from_layer(layer)
        .write()
        .non_parallel()
        .to_file(path)
        .map_err(|e| Error::io(path, format!("could not write OpenEXR ({e})")))
}

type Image2<L> = exr::image::Image<L>;

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
mod tests {
    use super::*;

    /// A fresh folder, removed with everything in it when dropped.
    fn temp_dir() -> tempfile::TempDir {
        tempfile::tempdir().unwrap()
    }

    fn ramp(width: usize, height: usize, channels: usize) -> Image {
        let data = (0..width * height * channels)
            .map(|i| i as f32 / 100.0)
            .collect();
        Image {
            width,
            height,
            channels,
            data,
        }
    }

    #[test]
    fn exr_round_trip_rgb_and_y() {
        let dir = temp_dir();
        for channels in [1, 3] {
            let path = dir.path().join(format!("ramp{channels}.exr"));
            let image = ramp(7, 5, channels);
            write_exr(&path, &image).unwrap();
            assert_eq!(read_exr(&path).unwrap(), image);
        }
    }

    /// Writes the 1-channel `image` as the data window at `position` of the display window
    /// `display`.
    fn write_windowed(path: &Path, image: &Image, position: (i32, i32), display: IntegerBounds) {
        let channels = AnyChannels::sort(SmallVec::from_vec(vec![AnyChannel::new(
            "Y",
            FlatSamples::F32(image.data.clone()),
        )]));
        let mut layer = Layer::new(
            (image.width, image.height),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            channels,
        );
        layer.attributes.layer_position = Vec2(position.0, position.1);
        Image2::new(ImageAttributes::new(display), layer)
            .write()
            .to_file(path)
            .unwrap();
    }

    #[test]
    fn exr_data_window_is_placed_in_the_display_window() {
        let dir = temp_dir();
        let path = dir.path().join("offset.exr");
        let data = ramp(3, 2, 1);
        write_windowed(&path, &data, (11, 21), IntegerBounds::new((10, 20), (4, 3)));
        let read = read_exr(&path).unwrap();
        assert_eq!((read.width, read.height, read.channels), (4, 3, 1));
        #[rustfmt::skip]
        let expected = [
            0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.01, 0.02,
            0.0, 0.03, 0.04, 0.05,
        ];
        assert_eq!(read.data, expected);
    }

    #[test]
    fn exr_data_outside_the_display_window_is_not_read() {
        let dir = temp_dir();
        let path = dir.path().join("overscan.exr");
        write_windowed(
            &path,
            &ramp(3, 3, 1),
            (-1, 1),
            IntegerBounds::new((0, 0), (2, 2)),
        );
        assert_eq!(read_exr(&path).unwrap().data, [0.0, 0.0, 0.01, 0.02]);
        write_windowed(
            &path,
            &ramp(3, 3, 1),
            (5, 5),
            IntegerBounds::new((0, 0), (2, 2)),
        );
        assert_eq!(read_exr(&path).unwrap().data, [0.0; 4]);
    }

    #[test]
    fn png_round_trip_keeps_16_bits() {
        let dir = temp_dir();
        let path = dir.path().join("ramp16.png");
        let image = Image {
            width: 3,
            height: 1,
            channels: 1,
            data: vec![0.0, 1.0 / 65535.0, 1.0],
        };
        write_png(&path, &image, 16).unwrap();
        let (back, bits) = read_png(&path).unwrap();
        assert_eq!(bits, 16);
        assert_eq!(back.data, image.data);
    }

    #[test]
    fn errors_name_the_file() {
        let dir = temp_dir();
        let path = dir.path().join("garbage.exr");
        std::fs::write(&path, b"not an exr").unwrap();
        let message = read_exr(&path).unwrap_err().to_string();
        assert!(
            message.starts_with(&path.display().to_string()),
            "{message}"
        );
        let missing = dir.path().join("missing.png");
        assert!(read_png(&missing)
            .unwrap_err()
            .to_string()
            .contains("missing.png"));
    }

    #[test]
    fn absurd_sizes_are_rejected_before_allocating() {
        let dir = temp_dir();
        let exr = dir.path().join("tiny.exr");
        write_exr(&exr, &ramp(4, 3, 3)).unwrap();
        let mut bytes = std::fs::read(&exr).unwrap();
        let window = bytes
            .windows(11)
            .position(|w| w == b"dataWindow\0")
            .unwrap()
            + b"dataWindow\0box2i\0".len()
            + 4;
        bytes[window + 8..window + 16]
            .copy_from_slice(&[0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00]);
        std::fs::write(&exr, &bytes).unwrap();
        let message = read_exr(&exr).unwrap_err().to_string();
        assert!(
            message.contains("tiny.exr") && message.contains("65537x65537 exceeds"),
            "{message}"
        );

        let png = dir.path().join("huge.png");
        let mut file = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        let header = [
            &1_000u32.to_be_bytes()[..],
            &1_000u32.to_be_bytes(),
            &[16, 2, 0, 0, 0],
        ]
        .concat();
        file.extend(png_chunk(b"IHDR", &header));
        file.extend(png_chunk(b"IDAT", &[0x78, 0x9c]));
        file.extend(png_chunk(b"IEND", &[]));
        std::fs::write(&png, &file).unwrap();
        let message = read_png(&png).unwrap_err().to_string();
        let expected = format!(
            "claims 1000x1000 pixels, more than its {} bytes can hold",
            file.len()
        );
        assert!(
            message.contains("huge.png") && message.contains(&expected),
            "{message}"
        );
    }

    fn png_chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
        let body = [&kind[..], data].concat();
        [
            &(data.len() as u32).to_be_bytes()[..],
            &body,
            &crc32(&body).to_be_bytes(),
        ]
        .concat()
    }

    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &byte in bytes {
            crc ^= u32::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn stack_rejects_size_mismatch() {
        let dir = temp_dir();
        let a = dir.path().join("a.exr");
        let b = dir.path().join("b.exr");
        write_exr(&a, &ramp(4, 4, 3)).unwrap();
        write_exr(&b, &ramp(4, 3, 3)).unwrap();
        let message = read_image_stack(&[a, b.clone()]).unwrap_err().to_string();
        assert!(
            message.contains("b.exr") && message.contains("differs"),
            "{message}"
        );
    }
}
