//! Image helpers: PNG/JPEG encoding through the `image` crate, flips and resizing of [`RgbImage`].

use std::io::Cursor;

use image::{ExtendedColorType, ImageEncoder, ImageFormat};

use crate::schema::RgbImage;

/// How RGB camera frames are compressed inside episode files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageCompression {
    /// Lossless PNG.
    Png,
    /// Lossy JPEG with the given quality (1–100).
    Jpeg {
        /// Quality 1–100.
        quality: u8,
    },
}

impl ImageCompression {
    /// The Foxglove `format` string (`png` or `jpeg`).
    pub fn format(&self) -> &'static str {
        match self {
            ImageCompression::Png => "png",
            ImageCompression::Jpeg { .. } => "jpeg",
        }
    }
}

/// Encodes an RGB image `[H, W, 3]` as PNG or JPEG.
pub fn encode_rgb(img: &RgbImage, compression: ImageCompression) -> Result<Vec<u8>, String> {
    if img.channels != 3 || !img.is_consistent() {
        return Err(format!(
            "RGB image must be [H, W, 3] with H*W*3 bytes, got {}x{}x{} with {} bytes",
            img.height,
            img.width,
            img.channels,
            img.data.len()
        ));
    }
    let mut out = Vec::with_capacity(img.data.len() / 4 + 64);
    let res = match compression {
        ImageCompression::Png => image::codecs::png::PngEncoder::new_with_quality(
            &mut out,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        )
        .write_image(&img.data, img.width, img.height, ExtendedColorType::Rgb8),
        ImageCompression::Jpeg { quality } => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100))
                .write_image(&img.data, img.width, img.height, ExtendedColorType::Rgb8)
        }
    };
    res.map_err(|e| format!("image encoding failed: {e}"))?;
    Ok(out)
}

/// Decodes PNG/JPEG bytes (`format` = `png` | `jpeg` | `jpg`, or empty to guess) to RGB `[H, W, 3]`.
pub fn decode_rgb(bytes: &[u8], format: &str) -> Result<RgbImage, String> {
    let img = decode_dynamic(bytes, format)?.to_rgb8();
    let (w, h) = img.dimensions();
    Ok(RgbImage {
        width: w,
        height: h,
        channels: 3,
        data: img.into_raw(),
    })
}

/// Decodes PNG/JPEG bytes to one 16-bit grey channel `[H, W]` (8-bit sources keep their values).
pub fn decode_gray16(bytes: &[u8], format: &str) -> Result<(u32, u32, Vec<u16>), String> {
    let img = decode_dynamic(bytes, format)?;
    let g = match img {
        image::DynamicImage::ImageLuma8(g) => {
            let (w, h) = g.dimensions();
            return Ok((w, h, g.into_raw().into_iter().map(u16::from).collect()));
        }
        other => other.to_luma16(),
    };
    let (w, h) = g.dimensions();
    Ok((w, h, g.into_raw()))
}

/// Decodes PNG/JPEG bytes to one 8-bit grey channel `[H, W]`.
pub fn decode_gray8(bytes: &[u8], format: &str) -> Result<(u32, u32, Vec<u8>), String> {
    let g = decode_dynamic(bytes, format)?.to_luma8();
    let (w, h) = g.dimensions();
    Ok((w, h, g.into_raw()))
}

fn decode_dynamic(bytes: &[u8], format: &str) -> Result<image::DynamicImage, String> {
    let fmt = match format.to_ascii_lowercase().as_str() {
        "png" => ImageFormat::Png,
        "jpeg" | "jpg" => ImageFormat::Jpeg,
        "" => image::guess_format(bytes).map_err(|e| format!("unknown image format: {e}"))?,
        other => return Err(format!("unsupported image format `{other}`")),
    };
    // The reader's default limits (512 MiB allocation) keep a damaged header from exhausting memory.
    image::ImageReader::with_format(Cursor::new(bytes), fmt)
        .decode()
        .map_err(|e| format!("image decoding failed: {e}"))
}

/// Orientation transform applied to a stored image to make it upright.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flip {
    /// Leave as is.
    None,
    /// Reverse the rows (upside down ↔ upright).
    Vertical,
    /// Reverse the columns (mirror).
    Horizontal,
    /// Rotate by 180° (both).
    Rotate180,
}

impl Flip {
    /// Short name used in metadata (`none`, `vflip`, `hflip`, `rot180`).
    pub fn name(&self) -> &'static str {
        match self {
            Flip::None => "none",
            Flip::Vertical => "vflip",
            Flip::Horizontal => "hflip",
            Flip::Rotate180 => "rot180",
        }
    }
}

/// Applies `flip` to an interleaved `[H, W, C]` buffer in place.
pub fn apply_flip<T: Copy>(
    data: &mut [T],
    width: usize,
    height: usize,
    channels: usize,
    flip: Flip,
) {
    let row = width * channels;
    debug_assert_eq!(data.len(), row * height);
    let (rows, cols) = match flip {
        Flip::None => return,
        Flip::Vertical => (true, false),
        Flip::Horizontal => (false, true),
        Flip::Rotate180 => (true, true),
    };
    if rows {
        for y in 0..height / 2 {
            let (top, bottom) = data.split_at_mut((height - 1 - y) * row);
            top[y * row..(y + 1) * row].swap_with_slice(&mut bottom[..row]);
        }
    }
    if cols {
        for y in 0..height {
            let r = &mut data[y * row..(y + 1) * row];
            for x in 0..width / 2 {
                for c in 0..channels {
                    r.swap(x * channels + c, (width - 1 - x) * channels + c);
                }
            }
        }
    }
}

/// Resizes RGB `[H, W, 3]` to `[h, w, 3]`: area averaging (`image::imageops::thumbnail`) when
/// shrinking in both directions, a triangle (bilinear) filter otherwise; returned as is if equal.
pub fn resize_rgb(img: RgbImage, width: u32, height: u32) -> RgbImage {
    if img.width == width && img.height == height {
        return img;
    }
    let (w0, h0) = (img.width, img.height);
    let Some(buf) = image::RgbImage::from_raw(w0, h0, img.data) else {
        return RgbImage::zeros(width, height, 3);
    };
    let out = if width <= w0 && height <= h0 {
        image::imageops::thumbnail(&buf, width, height)
    } else {
        image::imageops::resize(&buf, width, height, image::imageops::FilterType::Triangle)
    };
    RgbImage {
        width,
        height,
        channels: 3,
        data: out.into_raw(),
    }
}
