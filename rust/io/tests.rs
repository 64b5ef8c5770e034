//! Tests of image reading and writing.

use std::path::Path;

use exr::prelude::*;

use super::exr_image::{read_exr, write_exr, write_exr_compressed, ExrCompression, Image2};
use super::png_image::{read_png, write_png};
use super::stack::read_image_stack;
use super::Image;

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

#[test]
fn exr_round_trip_with_each_compression_as_the_header_says() {
    let dir = temp_dir();
    for (compression, expected) in [
        (ExrCompression::Zip, Compression::ZIP16),
        (ExrCompression::Rle, Compression::RLE),
    ] {
        let path = dir.path().join(format!("{compression:?}.exr"));
        let mut image = ramp(9, 6, 3);
        image.data[..30].fill(0.0);
        write_exr_compressed(&path, &image, compression).unwrap();
        assert_eq!(read_exr(&path).unwrap(), image);
        let meta = MetaData::read_from_file(&path, false).unwrap();
        assert_eq!(meta.headers[0].compression, expected);
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
