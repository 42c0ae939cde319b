//! The label image (`sensor_msgs/Image`: mono8/mono16 or 8UC1/16UC1 with one class id per
//! pixel, or rgb8/bgr8/rgba8/bgra8 painted in the segmenter's palette) and
//! `sensor_msgs/CameraInfo` (plumb_bob or no distortion) ↔ model types.

use crate::error::InputError;
use crate::msg::{sensor_msgs, std_msgs};
use sgm_model::perception::colour_ids::{ColourIds, Rgb};
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::perception::segmenters::NO_LABEL;

/// At most this many distinct unknown colours are counted one by one per image.
const MAX_UNKNOWN_COLOURS: usize = 32;

/// Pixels of a colour image whose colour the palette does not have (they carry no class).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct UnknownColours {
    /// Pixels per colour, the first [`MAX_UNKNOWN_COLOURS`] colours of the image.
    pub colours: Vec<(Rgb, u32)>,
    /// Pixels of further colours.
    pub other: u32,
}

impl UnknownColours {
    fn add(&mut self, rgb: Rgb) {
        if let Some((_, n)) = self.colours.iter_mut().find(|(c, _)| *c == rgb) {
            *n += 1;
        } else if self.colours.len() < MAX_UNKNOWN_COLOURS {
            self.colours.push((rgb, 1));
        } else {
            self.other += 1;
        }
    }
}

/// How a pixel is stored.
#[derive(Clone, Copy)]
enum PixelFormat {
    Mono8,
    Mono16,
    /// Bytes per pixel, and whether the colour is stored blue first.
    Colour {
        bytes: usize,
        bgr: bool,
    },
}

/// A label image from a message, whatever its row padding and byte order; colour images are
/// read back to pixel values through `colours` (a colour it lacks carries no class and is
/// counted in the [`UnknownColours`]).
pub fn read_label_image(
    msg: &sensor_msgs::Image,
    colours: Option<&ColourIds>,
) -> Result<(LabelImage, UnknownColours), InputError> {
    let format = match (msg.encoding.as_str(), colours) {
        ("mono8" | "8UC1", _) => PixelFormat::Mono8,
        ("mono16" | "16UC1", _) => PixelFormat::Mono16,
        ("rgb8", Some(_)) => PixelFormat::Colour { bytes: 3, bgr: false },
        ("bgr8", Some(_)) => PixelFormat::Colour { bytes: 3, bgr: true },
        ("rgba8", Some(_)) => PixelFormat::Colour { bytes: 4, bgr: false },
        ("bgra8", Some(_)) => PixelFormat::Colour { bytes: 4, bgr: true },
        ("rgb8" | "bgr8" | "rgba8" | "bgra8", None) => {
            return Err(InputError::invalid(format!(
                "a colour label image ({}) and no palette to read it",
                msg.encoding
            )))
        }
        (other, _) => return Err(InputError::Encoding(other.to_string())),
    };
    let bytes_per_pixel = match format {
        PixelFormat::Mono8 => 1usize,
        PixelFormat::Mono16 => 2,
        PixelFormat::Colour { bytes, .. } => bytes,
    };
    let (w, h) = (msg.width as usize, msg.height as usize);
    if w == 0 || h == 0 {
        return Err(InputError::invalid(format!("image is {w} × {h}")));
    }
    let row = w * bytes_per_pixel;
    if (msg.step as usize) < row {
        return Err(InputError::invalid(format!("step {} is less than width {w} × {bytes_per_pixel} bytes", msg.step)));
    }
    let needed = msg.step as usize * (h - 1) + row;
    if msg.data.len() < needed {
        return Err(InputError::Truncated {
            got: msg.data.len(),
            expected: needed,
            what: format!("{w} × {h} {} image, step {}", msg.encoding, msg.step),
        });
    }
    let mut labels = Vec::with_capacity(w * h);
    let mut unknown = UnknownColours::default();
    // Segmentations come in runs: the last colour's id is kept.
    let mut last: Option<(Rgb, Option<u16>)> = None;
    for r in 0..h {
        let row_bytes = &msg.data[r * msg.step as usize..][..row];
        match (format, colours) {
            (PixelFormat::Mono8, _) => labels.extend(row_bytes.iter().map(|&b| u16::from(b))),
            (PixelFormat::Mono16, _) if msg.is_bigendian != 0 => {
                labels.extend(row_bytes.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])))
            }
            (PixelFormat::Mono16, _) => {
                labels.extend(row_bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])))
            }
            (PixelFormat::Colour { bytes: 3, bgr }, Some(ids)) => {
                read_colours::<3>(row_bytes, bgr, ids, &mut last, &mut unknown, &mut labels)
            }
            (PixelFormat::Colour { bgr, .. }, Some(ids)) => {
                read_colours::<4>(row_bytes, bgr, ids, &mut last, &mut unknown, &mut labels)
            }
            (PixelFormat::Colour { .. }, None) => return Err(InputError::Encoding(msg.encoding.clone())),
        }
    }
    let image = LabelImage::new(msg.width, msg.height, labels).map_err(|e| InputError::invalid(e.to_string()))?;
    Ok((image, unknown))
}

/// One row of `N`-byte colour pixels (RGB or BGR first, alpha ignored) to pixel values.
fn read_colours<const N: usize>(
    row: &[u8],
    bgr: bool,
    ids: &ColourIds,
    last: &mut Option<(Rgb, Option<u16>)>,
    unknown: &mut UnknownColours,
    labels: &mut Vec<u16>,
) {
    for p in row.chunks_exact(N) {
        let rgb = if bgr { [p[2], p[1], p[0]] } else { [p[0], p[1], p[2]] };
        let id = match *last {
            Some((c, id)) if c == rgb => id,
            _ => {
                let id = ids.id(rgb);
                *last = Some((rgb, id));
                id
            }
        };
        if id.is_none() {
            unknown.add(rgb);
        }
        labels.push(id.unwrap_or(NO_LABEL));
    }
}

/// mono8 when every label fits in a byte, else little-endian mono16.
pub fn label_image_msg(header: std_msgs::Header, image: &LabelImage) -> sensor_msgs::Image {
    let wide = image.labels.iter().any(|&l| l > 255);
    let data: Vec<u8> = if wide {
        image.labels.iter().flat_map(|l| l.to_le_bytes()).collect()
    } else {
        image.labels.iter().map(|&l| l as u8).collect()
    };
    sensor_msgs::Image {
        header,
        height: image.height,
        width: image.width,
        encoding: if wide { "mono16" } else { "mono8" }.into(),
        is_bigendian: 0,
        step: image.width * if wide { 2 } else { 1 },
        data,
    }
}

/// Intrinsics from K and the distortion from D (plumb_bob k1 k2 p1 p2 k3, or none).
pub fn read_camera_info(msg: &sensor_msgs::CameraInfo) -> Result<CameraModel, InputError> {
    let k = &msg.K;
    let (fx, fy, cx, cy) = (k[0], k[4], k[2], k[5]);
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0 && cx.is_finite() && cy.is_finite()) {
        return Err(InputError::invalid(format!(
            "K has fx {fx}, fy {fy}, cx {cx}, cy {cy}: finite, fx and fy > 0 expected"
        )));
    }
    if msg.width == 0 || msg.height == 0 {
        return Err(InputError::invalid(format!("camera is {} × {}", msg.width, msg.height)));
    }
    let mut distortion = [0.0; 5];
    match msg.distortion_model.as_str() {
        "" if msg.D.iter().all(|&d| d == 0.0) => {}
        "plumb_bob" | "rational_polynomial" if msg.D.len() >= 5 || msg.D.iter().all(|&d| d == 0.0) => {
            if msg.distortion_model == "rational_polynomial" && msg.D.iter().skip(5).any(|&d| d != 0.0) {
                return Err(InputError::invalid("rational_polynomial with k4..k6 ≠ 0 is not supported (plumb_bob is)"));
            }
            for (slot, d) in distortion.iter_mut().zip(&msg.D) {
                *slot = *d;
            }
        }
        other => {
            return Err(InputError::invalid(format!(
                "distortion model `{other}` with {} coefficients (plumb_bob with 5 expected)",
                msg.D.len()
            )))
        }
    }
    if !distortion.iter().all(|d| d.is_finite()) {
        return Err(InputError::invalid("D has a non-finite coefficient"));
    }
    Ok(CameraModel { width: msg.width, height: msg.height, fx, fy, cx, cy, distortion })
}

pub fn camera_info_msg(header: std_msgs::Header, camera: &CameraModel) -> sensor_msgs::CameraInfo {
    let CameraModel { fx, fy, cx, cy, .. } = *camera;
    sensor_msgs::CameraInfo {
        header,
        height: camera.height,
        width: camera.width,
        distortion_model: "plumb_bob".into(),
        D: camera.distortion.to_vec(),
        K: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_images_round_trip_in_both_widths() {
        for labels in [vec![0u16, 3, 255, 7, 1, 2], vec![0u16, 3, 65535, 7, 1, 300]] {
            let image = LabelImage::new(3, 2, labels).unwrap();
            let msg = label_image_msg(std_msgs::Header::default(), &image);
            assert_eq!(read_label_image(&msg, None).unwrap().0, image);
        }
    }

    #[test]
    fn padded_big_endian_mono16() {
        let msg = sensor_msgs::Image {
            width: 2,
            height: 2,
            encoding: "16UC1".into(),
            is_bigendian: 1,
            step: 6,
            data: vec![0, 1, 1, 0, 9, 9, 0, 2, 0, 3],
            ..Default::default()
        };
        assert_eq!(read_label_image(&msg, None).unwrap().0.labels, vec![1, 256, 2, 3]);
    }

    #[test]
    fn bad_images_and_cameras_are_refused() {
        let image = LabelImage::new(4, 4, vec![1; 16]).unwrap();
        let good = label_image_msg(std_msgs::Header::default(), &image);
        let mut m = good.clone();
        m.encoding = "yuv422".into();
        assert_eq!(
            read_label_image(&m, None).unwrap_err().to_string(),
            "unsupported encoding `yuv422` (mono8, mono16, 8UC1, 16UC1, rgb8, bgr8, rgba8 or bgra8 expected)"
        );
        let mut m = good.clone();
        m.data.truncate(10);
        assert_eq!(
            read_label_image(&m, None).unwrap_err().to_string(),
            "data is 10 bytes, 16 expected (4 × 4 mono8 image, step 4)"
        );
        let mut m = good;
        m.step = 2;
        assert!(read_label_image(&m, None).is_err());

        let camera = CameraModel {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 501.0,
            cx: 320.5,
            cy: 240.0,
            distortion: [0.1, -0.01, 0.001, 0.002, 0.0],
        };
        let info = camera_info_msg(std_msgs::Header::default(), &camera);
        assert_eq!(read_camera_info(&info).unwrap(), camera);
        let mut bad = info.clone();
        bad.K[0] = 0.0;
        assert!(read_camera_info(&bad).unwrap_err().to_string().contains("fx 0"));
        let mut bad = info.clone();
        bad.distortion_model = "equidistant".into();
        assert!(read_camera_info(&bad).unwrap_err().to_string().contains("`equidistant`"));
        let mut bad = info;
        bad.D = vec![0.1];
        assert!(read_camera_info(&bad).is_err());
    }

    /// An ADE20K segmentation painted in mmsegmentation's palette, as rgb8 and as padded bgra8:
    /// wall, chair and a colour the palette lacks (no class, counted by colour).
    #[test]
    fn colour_images_read_back_through_the_palette() {
        use sgm_model::perception::classes::ClassTable;
        use sgm_model::perception::label_map::LabelMapSpec;
        let spec = LabelMapSpec { segmenter: "ade20k_150".into(), ..Default::default() };
        let classes = ClassTable::new(vec![sgm_model::perception::classes::ClassSpec {
            name: "chair".into(),
            id: 6,
            colour: [0, 0, 0],
            matchable: true,
            object: true,
            dynamic: false,
            min_points: 5,
            max_points: 100,
            max_extent_m: 2.0,
        }])
        .unwrap();
        let ids = ColourIds::new(&spec, &classes).unwrap();
        let (wall, chair, odd) = ([120u8, 120, 120], [204u8, 70, 3], [1u8, 2, 3]);
        let rgb: Vec<u8> = [wall, chair, chair, odd].concat();
        let msg = sensor_msgs::Image {
            width: 2,
            height: 2,
            encoding: "rgb8".into(),
            step: 6,
            data: rgb,
            ..Default::default()
        };
        let (image, unknown) = read_label_image(&msg, Some(&ids)).unwrap();
        assert_eq!(image.labels, vec![0, 19, 19, NO_LABEL]);
        assert_eq!(unknown, UnknownColours { colours: vec![(odd, 1)], other: 0 });
        let bgra: Vec<u8> = [wall, chair, chair, odd].iter().flat_map(|c| [c[2], c[1], c[0], 255]).collect();
        let mut data = Vec::new();
        data.extend_from_slice(&bgra[..8]);
        data.extend_from_slice(&[9, 9]);
        data.extend_from_slice(&bgra[8..]);
        let msg =
            sensor_msgs::Image { width: 2, height: 2, encoding: "bgra8".into(), step: 10, data, ..Default::default() };
        assert_eq!(read_label_image(&msg, Some(&ids)).unwrap().0.labels, vec![0, 19, 19, NO_LABEL]);
        // Without a palette a colour image is refused.
        let e = read_label_image(&msg, None).unwrap_err().to_string();
        assert_eq!(e, "a colour label image (bgra8) and no palette to read it");
    }
}
