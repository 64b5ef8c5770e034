//! OpenEXR images of float R, G, B or Y channels.
//!
//! An EXR image is its display window: its data window's pixels are placed where that
//! window lies in it, the display window's pixels outside the data window are 0 and data
//! outside the display window is not read.

use std::path::Path;

use exr::prelude::*;

use crate::error::{Error, Result};
use crate::memory::{check_available, try_collect, try_vec};

use super::{check_data_len, check_size, Image};

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

/// How an OpenEXR file's pixels are compressed; both are lossless.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExrCompression {
    /// Deflate over blocks of 16 rows: the smaller file.
    #[default]
    Zip,
    /// Runs of equal bytes: several times faster to write, nearly as small for images that
    /// are mostly one value (an object's inter-reflected light, 0 around it).
    Rle,
}

/// Writes a 1-channel (Y) or 3-channel (R, G, B) image as 32-bit float OpenEXR, zip-compressed.
pub fn write_exr(path: &Path, image: &Image) -> Result<()> {
    write_exr_compressed(path, image, ExrCompression::Zip)
}

/// [`write_exr`] with the compression `compression`.
pub fn write_exr_compressed(path: &Path, image: &Image, compression: ExrCompression) -> Result<()> {
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
    layer.encoding.compression = match compression {
        ExrCompression::Zip => Compression::ZIP16,
        ExrCompression::Rle => Compression::RLE,
    };
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

pub(super) type Image2<L> = exr::image::Image<L>;
