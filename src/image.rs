//! Camera images as hosts hand them over: a borrowed pixel buffer with width, height, row
//! stride and pixel format, validated before anything reads it.

use crate::errors::VisionError;
use opencv::core::{Mat, Size, CV_8UC1, CV_8UC3, CV_8UC4};
use opencv::prelude::*;

/// Largest accepted width or height, in pixels; larger images are refused (not resized) so
/// that a corrupt header cannot make the library allocate gigabytes.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Layout of one pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelFormat {
    /// 8-bit grey.
    Gray8,
    /// 8-bit red, green, blue.
    Rgb8,
    /// 8-bit blue, green, red (OpenCV's order).
    Bgr8,
    /// 8-bit red, green, blue, alpha.
    Rgba8,
    /// 8-bit blue, green, red, alpha.
    Bgra8,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub fn channels(self) -> usize {
        match self {
            PixelFormat::Gray8 => 1,
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => 3,
            PixelFormat::Rgba8 | PixelFormat::Bgra8 => 4,
        }
    }
}

/// A borrowed image: `height` rows of `stride` bytes, each starting with `width` pixels.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Bytes from the start of one row to the next (>= width x channels).
    pub stride: usize,
    /// Pixel layout.
    pub format: PixelFormat,
    /// The pixels; at least `stride x (height - 1) + width x channels` bytes.
    pub data: &'a [u8],
}

impl<'a> ImageView<'a> {
    /// A tightly packed image (stride = width x channels).
    pub fn packed(width: u32, height: u32, format: PixelFormat, data: &'a [u8]) -> Self {
        Self {
            width,
            height,
            stride: width as usize * format.channels(),
            format,
            data,
        }
    }

    /// Checks size, stride and buffer length; every reader calls this first.
    pub fn validate(&self) -> Result<(), VisionError> {
        let bad = |msg: String| Err(VisionError::InvalidImage(msg));
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image is {}x{}: width and height must be positive",
                self.width, self.height
            ));
        }
        if self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return bad(format!(
                "image is {}x{}, larger than {MAX_IMAGE_SIDE} pixels on a side",
                self.width, self.height
            ));
        }
        let row = self.width as usize * self.format.channels();
        if self.stride < row {
            return bad(format!(
                "stride {} is smaller than a row of {} pixels ({row} bytes)",
                self.stride, self.width
            ));
        }
        let Some(needed) = self
            .stride
            .checked_mul(self.height as usize - 1)
            .and_then(|rows| rows.checked_add(row))
        else {
            return bad(format!(
                "stride {} times {} rows overflows the address space",
                self.stride, self.height
            ));
        };
        if self.data.len() < needed {
            return bad(format!(
                "buffer holds {} bytes, a {}x{} image with stride {} needs {needed}",
                self.data.len(),
                self.width,
                self.height,
                self.stride
            ));
        }
        Ok(())
    }

    /// Converts to an owned 8-bit RGB OpenCV matrix resized to `size` (area interpolation when
    /// shrinking, linear when enlarging).
    pub(crate) fn to_rgb_resized(self, size: Size) -> Result<Mat, VisionError> {
        self.validate()?;
        let kind = match self.format.channels() {
            1 => CV_8UC1,
            3 => CV_8UC3,
            _ => CV_8UC4,
        };
        // SAFETY: validate() checked that `data` covers height rows of `stride` bytes; the Mat
        // header only borrows the buffer within this function, and is cloned before returning.
        let borrowed = unsafe {
            Mat::new_rows_cols_with_data_unsafe(
                self.height as i32,
                self.width as i32,
                kind,
                self.data.as_ptr() as *mut std::ffi::c_void,
                self.stride,
            )
        }?;
        // Resized in the image's own format, then converted: the same pixels (resizing works
        // per channel, the conversions copy or reorder channels), on fewer of them.
        let shrinking = size.width < self.width as i32 || size.height < self.height as i32;
        let interpolation = if shrinking {
            opencv::imgproc::INTER_AREA
        } else {
            opencv::imgproc::INTER_LINEAR
        };
        let mut resized = Mat::default();
        opencv::imgproc::resize(&borrowed, &mut resized, size, 0.0, 0.0, interpolation)?;
        let code = match self.format {
            PixelFormat::Gray8 => opencv::imgproc::COLOR_GRAY2RGB,
            PixelFormat::Rgb8 => return Ok(resized),
            PixelFormat::Bgr8 => opencv::imgproc::COLOR_BGR2RGB,
            PixelFormat::Rgba8 => opencv::imgproc::COLOR_RGBA2RGB,
            PixelFormat::Bgra8 => opencv::imgproc::COLOR_BGRA2RGB,
        };
        let mut rgb = Mat::default();
        opencv::imgproc::cvt_color_def(&resized, &mut rgb, code)?;
        Ok(rgb)
    }
}

/// Reads an image file (any format OpenCV decodes) as packed RGB8 bytes with its size.
pub fn read_rgb(path: &std::path::Path) -> Result<(u32, u32, Vec<u8>), VisionError> {
    let bgr = read_mat(path, opencv::imgcodecs::IMREAD_COLOR)?;
    if bgr.empty() {
        return Err(VisionError::InvalidImage(format!(
            "cannot read image '{}'",
            path.display()
        )));
    }
    let mut rgb = Mat::default();
    opencv::imgproc::cvt_color_def(&bgr, &mut rgb, opencv::imgproc::COLOR_BGR2RGB)?;
    let bytes = rgb.data_bytes()?.to_vec();
    Ok((rgb.cols() as u32, rgb.rows() as u32, bytes))
}

/// Reads a 16-bit single-channel image (a depth PNG) as `(width, height, row-major values)`.
/// Fails, naming the file, when it is missing, does not decode, or is not 16-bit with one
/// channel.
pub fn read_u16(path: &std::path::Path) -> Result<(u32, u32, Vec<u16>), VisionError> {
    let mat = read_mat(path, opencv::imgcodecs::IMREAD_ANYDEPTH)?;
    if mat.empty() || mat.typ() != opencv::core::CV_16UC1 {
        return Err(VisionError::InvalidImage(format!(
            "'{}' is not a 16-bit single-channel image",
            path.display()
        )));
    }
    let values = mat.data_typed::<u16>()?.to_vec();
    Ok((mat.cols() as u32, mat.rows() as u32, values))
}

/// `imread` of an existing file with a UTF-8 path (the Mat may be empty: it did not decode).
fn read_mat(path: &std::path::Path, flags: i32) -> Result<Mat, VisionError> {
    let name = path.to_str().ok_or_else(|| {
        VisionError::InvalidImage(format!("path {} is not UTF-8", path.display()))
    })?;
    if !path.is_file() {
        return Err(VisionError::InvalidImage(format!(
            "cannot read image '{}': no such file",
            path.display()
        )));
    }
    Ok(opencv::imgcodecs::imread(name, flags)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_buffers_are_refused_with_a_reason() {
        let data = vec![0u8; 64 * 48 * 3];
        let ok = ImageView::packed(64, 48, PixelFormat::Rgb8, &data);
        assert!(ok.validate().is_ok());
        let cases = [
            (ImageView { width: 0, ..ok }, "positive"),
            (ImageView { height: 0, ..ok }, "positive"),
            (
                ImageView {
                    width: 10_000,
                    height: 10_000,
                    ..ok
                },
                "larger than",
            ),
            (
                ImageView {
                    stride: 64 * 3 - 1,
                    ..ok
                },
                "stride",
            ),
            (
                ImageView {
                    data: &data[..data.len() - 1],
                    ..ok
                },
                "needs",
            ),
            (
                ImageView {
                    format: PixelFormat::Rgba8,
                    ..ok
                },
                "stride",
            ),
        ];
        for (image, why) in cases {
            match image.validate() {
                Err(VisionError::InvalidImage(msg)) => assert!(msg.contains(why), "{msg}"),
                other => panic!("{image:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn every_format_converts_to_rgb_with_padding_rows() {
        // 2x1 image, stride 16 (padded rows), pixel 0 red-ish, pixel 1 blue-ish.
        let cases: [(PixelFormat, [u8; 8]); 5] = [
            (PixelFormat::Rgb8, [200, 10, 20, 30, 40, 250, 0, 0]),
            (PixelFormat::Bgr8, [20, 10, 200, 250, 40, 30, 0, 0]),
            (PixelFormat::Rgba8, [200, 10, 20, 255, 30, 40, 250, 255]),
            (PixelFormat::Bgra8, [20, 10, 200, 255, 250, 40, 30, 255]),
            (PixelFormat::Gray8, [90, 90, 0, 0, 0, 0, 0, 0]),
        ];
        for (format, pixels) in cases {
            let mut data = vec![0u8; 16];
            data[..8].copy_from_slice(&pixels);
            let image = ImageView {
                width: 2,
                height: 1,
                stride: 16,
                format,
                data: &data,
            };
            let rgb = image.to_rgb_resized(Size::new(2, 1)).unwrap();
            let bytes = rgb.data_bytes().unwrap();
            let expected: &[u8] = if format == PixelFormat::Gray8 {
                &[90, 90, 90, 90, 90, 90]
            } else {
                &[200, 10, 20, 30, 40, 250]
            };
            assert_eq!(bytes, expected, "{format:?}");
        }
    }

    #[test]
    fn sixteen_bit_images_read_back_and_others_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let values: Vec<u16> = (0..12).map(|i| i * 5000).collect();
        let mat = Mat::new_rows_cols_with_data::<u16>(3, 4, &values).unwrap();
        let path = dir.path().join("depth.png");
        let name = path.to_str().unwrap();
        assert!(opencv::imgcodecs::imwrite_def(name, &mat).unwrap());
        assert_eq!(read_u16(&path).unwrap(), (4, 3, values));

        let grey = Mat::new_rows_cols_with_default(3, 4, opencv::core::CV_8UC1, 7.into()).unwrap();
        let eight = dir.path().join("grey.png");
        assert!(opencv::imgcodecs::imwrite_def(eight.to_str().unwrap(), &grey).unwrap());
        let err = read_u16(&eight).unwrap_err().to_string();
        assert!(err.contains("grey.png") && err.contains("16-bit"), "{err}");
        let err = read_u16(&dir.path().join("none.png"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("no such file"), "{err}");
    }
}
