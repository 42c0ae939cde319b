//! A cloud read into a [`Scan`]: `x`, `y`, `z` as float32 or float64 at any offsets, either byte
//! order, organised or not, points with a non-finite coordinate dropped, an optional integer
//! label field, and each point's time when the driver gives it, as seconds after the header's
//! stamp:
//!
//! | field | drivers | read as |
//! |---|---|---|
//! | `time` (float32/64) | velodyne_pointcloud, LIO-SAM, Hesai (relative) | seconds after the stamp |
//! | `t` (uint32) | ouster_ros | nanoseconds after the stamp |
//! | `timestamp` (float64) | livox_ros_driver2 (absolute ns), hesai_ros (absolute s) | minus the stamp: > 10¹⁵ as ns, > 10⁶ as s, else already relative |

use super::datatypes::{type_name, type_size, FLOAT32, FLOAT64, INT16, INT32, INT8, UINT16, UINT32, UINT8};
use super::NO_LABEL;
use crate::error::InputError;
use crate::msg::sensor_msgs;
use nalgebra::Point3;

/// Where a field sits in a point and how to read it.
#[derive(Clone, Copy, Debug)]
struct Field {
    offset: usize,
    datatype: u8,
}

impl Field {
    fn find(
        msg: &sensor_msgs::PointCloud2,
        name: &str,
        allowed: &[u8],
        expected: &'static str,
    ) -> Result<Option<Field>, InputError> {
        let Some(f) = msg.fields.iter().find(|f| f.name == name) else { return Ok(None) };
        if !allowed.contains(&f.datatype) {
            return Err(InputError::FieldType {
                field: name.into(),
                datatype: f.datatype,
                found: type_name(f.datatype),
                expected,
            });
        }
        let size = type_size(f.datatype).unwrap_or(0);
        if f.offset.checked_add(size).is_none_or(|end| end > msg.point_step) {
            return Err(InputError::FieldOutsidePoint {
                field: name.into(),
                offset: f.offset,
                point_step: msg.point_step,
            });
        }
        Ok(Some(Field { offset: f.offset as usize, datatype: f.datatype }))
    }

    fn bytes<const N: usize>(&self, point: &[u8], big_endian: bool) -> [u8; N] {
        let mut b = [0u8; N];
        b.copy_from_slice(&point[self.offset..self.offset + N]);
        if big_endian {
            b.reverse();
        }
        b
    }

    fn float(&self, point: &[u8], big_endian: bool) -> f64 {
        match self.datatype {
            FLOAT64 => f64::from_le_bytes(self.bytes(point, big_endian)),
            _ => f64::from(f32::from_le_bytes(self.bytes(point, big_endian))),
        }
    }

    fn integer(&self, point: &[u8], big_endian: bool) -> i64 {
        match self.datatype {
            INT8 => i64::from(point[self.offset] as i8),
            UINT8 => i64::from(point[self.offset]),
            INT16 => i64::from(i16::from_le_bytes(self.bytes(point, big_endian))),
            UINT16 => i64::from(u16::from_le_bytes(self.bytes(point, big_endian))),
            INT32 => i64::from(i32::from_le_bytes(self.bytes(point, big_endian))),
            _ => i64::from(u32::from_le_bytes(self.bytes(point, big_endian))),
        }
    }
}

/// A scan read from a cloud message.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    pub points: Vec<Point3<f64>>,
    /// Per-point label values when the cloud has the label field.
    pub labels: Option<Vec<u16>>,
    /// Points dropped for a non-finite coordinate.
    pub dropped_non_finite: usize,
    /// Each point's time after the header's stamp, s, when the cloud has a time field.
    pub times: Option<Vec<f32>>,
}

/// A cloud's per-point time field and how its values become seconds after the stamp.
#[derive(Clone, Copy, Debug)]
enum TimeField {
    /// `time`: seconds after the stamp.
    Seconds(Field),
    /// `t`: nanoseconds after the stamp.
    Nanoseconds(Field),
    /// `timestamp`: absolute (ns or s) or relative seconds.
    Timestamp(Field),
}

impl TimeField {
    fn find(msg: &sensor_msgs::PointCloud2) -> Result<Option<Self>, InputError> {
        if let Some(f) = Field::find(msg, "time", &[FLOAT32, FLOAT64], "float32 or float64")? {
            return Ok(Some(Self::Seconds(f)));
        }
        if let Some(f) = Field::find(msg, "t", &[UINT32], "uint32 (nanoseconds)")? {
            return Ok(Some(Self::Nanoseconds(f)));
        }
        Ok(Field::find(msg, "timestamp", &[FLOAT64], "float64")?.map(Self::Timestamp))
    }

    /// Seconds after the stamp (`stamp_s`, the header's).
    fn after(&self, point: &[u8], big_endian: bool, stamp_s: f64) -> f64 {
        match self {
            Self::Seconds(f) => f.float(point, big_endian),
            Self::Nanoseconds(f) => f.integer(point, big_endian) as f64 * 1e-9,
            Self::Timestamp(f) => {
                let v = f.float(point, big_endian);
                if v > 1e15 {
                    (v - stamp_s * 1e9) * 1e-9
                } else if v > 1e6 {
                    v - stamp_s
                } else {
                    v
                }
            }
        }
    }
}

/// Reads the points (and the `label_field`, if named and present) of a cloud.
pub fn read_cloud(msg: &sensor_msgs::PointCloud2, label_field: &str) -> Result<Scan, InputError> {
    let coordinate = |name: &str| -> Result<Field, InputError> {
        Field::find(msg, name, &[FLOAT32, FLOAT64], "float32 or float64")?
            .ok_or_else(|| InputError::MissingField { field: name.into() })
    };
    let (x, y, z) = (coordinate("x")?, coordinate("y")?, coordinate("z")?);
    let label = if label_field.is_empty() {
        None
    } else {
        Field::find(msg, label_field, &[INT8, UINT8, INT16, UINT16, INT32, UINT32], "an integer type")?
    };
    let count = u64::from(msg.width) * u64::from(msg.height);
    let step = msg.point_step as usize;
    let row_bytes = u64::from(msg.width) * u64::from(msg.point_step);
    if u64::from(msg.row_step) < row_bytes {
        return Err(InputError::invalid(format!(
            "row_step {} is less than width {} × point_step {}",
            msg.row_step, msg.width, msg.point_step
        )));
    }
    let needed = if msg.height == 0 { 0 } else { u64::from(msg.row_step) * u64::from(msg.height - 1) + row_bytes };
    if (msg.data.len() as u64) < needed {
        return Err(InputError::Truncated {
            got: msg.data.len(),
            expected: needed as usize,
            what: format!("{} × {} points of {} bytes", msg.width, msg.height, msg.point_step),
        });
    }
    let time = TimeField::find(msg)?;
    let stamp_s = f64::from(msg.header.stamp.sec) + f64::from(msg.header.stamp.nsec) * 1e-9;
    let be = msg.is_bigendian;
    let mut scan = Scan {
        points: Vec::with_capacity(count as usize),
        labels: label.map(|_| Vec::with_capacity(count as usize)),
        dropped_non_finite: 0,
        times: time.map(|_| Vec::with_capacity(count as usize)),
    };
    for row in 0..msg.height as usize {
        let row_data = &msg.data[row * msg.row_step as usize..][..msg.width as usize * step];
        for point in row_data.chunks_exact(step) {
            let p = Point3::new(x.float(point, be), y.float(point, be), z.float(point, be));
            if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
                scan.dropped_non_finite += 1;
                continue;
            }
            scan.points.push(p);
            if let (Some(field), Some(labels)) = (label, scan.labels.as_mut()) {
                labels.push(u16::try_from(field.integer(point, be)).unwrap_or(NO_LABEL));
            }
            if let (Some(field), Some(times)) = (time, scan.times.as_mut()) {
                times.push(field.after(point, be, stamp_s) as f32);
            }
        }
    }
    Ok(scan)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::cloud::write::{cloud_msg, point_field};
    use crate::msg::std_msgs;
    use proptest::prelude::*;

    /// Drivers' point layouts: (field, offset, datatype), point step.
    type Layout = (&'static [(&'static str, u32, u8)], u32);
    /// velodyne_pointcloud's PointXYZIRT.
    const VELODYNE: Layout = (
        &[
            ("x", 0, FLOAT32),
            ("y", 4, FLOAT32),
            ("z", 8, FLOAT32),
            ("intensity", 12, FLOAT32),
            ("ring", 16, UINT16),
            ("time", 18, FLOAT32),
        ],
        22,
    );
    /// livox_ros_driver2's PointXYZRTLT.
    const LIVOX: Layout = (
        &[
            ("x", 0, FLOAT32),
            ("y", 4, FLOAT32),
            ("z", 8, FLOAT32),
            ("intensity", 12, FLOAT32),
            ("tag", 16, UINT8),
            ("line", 17, UINT8),
            ("timestamp", 18, FLOAT64),
        ],
        26,
    );
    /// ouster_ros's PointOS1 (x y z padded to 16 bytes, 48-byte points).
    const OUSTER: Layout = (
        &[
            ("x", 0, FLOAT32),
            ("y", 4, FLOAT32),
            ("z", 8, FLOAT32),
            ("intensity", 16, FLOAT32),
            ("t", 20, UINT32),
            ("reflectivity", 24, UINT16),
            ("ring", 26, UINT16),
            ("ambient", 28, UINT16),
            ("range", 32, UINT32),
        ],
        48,
    );

    /// A cloud of `points` in a driver's `layout`, either byte order, built field by field;
    /// padding bytes are 0xEE and every other field holds the point's index.
    fn layout_cloud((fields, step): Layout, points: &[[f32; 3]], big_endian: bool) -> sensor_msgs::PointCloud2 {
        let mut data = vec![0xEE; points.len() * step as usize];
        for (k, (p, point)) in points.iter().zip(data.chunks_mut(step as usize)).enumerate() {
            for &(name, offset, datatype) in fields {
                let mut bytes = match (name, datatype) {
                    ("x", _) => p[0].to_le_bytes().to_vec(),
                    ("y", _) => p[1].to_le_bytes().to_vec(),
                    ("z", _) => p[2].to_le_bytes().to_vec(),
                    (_, FLOAT32) => (k as f32).to_le_bytes().to_vec(),
                    (_, FLOAT64) => (k as f64).to_le_bytes().to_vec(),
                    (_, UINT8) => vec![k as u8],
                    (_, UINT16) => (k as u16).to_le_bytes().to_vec(),
                    _ => (k as u32).to_le_bytes().to_vec(),
                };
                if big_endian {
                    bytes.reverse();
                }
                point[offset as usize..offset as usize + bytes.len()].copy_from_slice(&bytes);
            }
        }
        sensor_msgs::PointCloud2 {
            height: 1,
            width: points.len() as u32,
            fields: fields.iter().map(|&(name, offset, datatype)| point_field(name, offset, datatype)).collect(),
            is_bigendian: big_endian,
            point_step: step,
            row_step: step * points.len() as u32,
            data,
            ..Default::default()
        }
    }

    #[test]
    fn driver_layouts_either_byte_order_nan_dropped() {
        let pts = [[1.0, 2.0, 3.0], [f32::NAN, 0.0, 0.0], [-4.5, 0.25, 1e3]];
        for (layout, name) in [(VELODYNE, "velodyne"), (LIVOX, "livox"), (OUSTER, "ouster")] {
            for be in [false, true] {
                let scan = read_cloud(&layout_cloud(layout, &pts, be), "label").unwrap();
                assert_eq!(scan.points, vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-4.5, 0.25, 1000.0)], "{name}");
                assert_eq!(scan.dropped_non_finite, 1);
                assert_eq!(scan.labels, None);
            }
        }
        // An integer field anywhere in the point read as labels: Velodyne's and Ouster's
        // uint16 ring, Livox's uint8 line.
        for (layout, field) in [(VELODYNE, "ring"), (OUSTER, "ring"), (LIVOX, "line")] {
            let scan = read_cloud(&layout_cloud(layout, &pts, true), field).unwrap();
            assert_eq!(scan.labels, Some(vec![0, 2]), "{field}");
        }
    }

    #[test]
    fn point_times_are_read_as_seconds_after_the_stamp_in_every_drivers_convention() {
        let pts = [[1.0, 2.0, 3.0], [f32::NAN, 0.0, 0.0], [-4.5, 0.25, 1e3]];
        // The time fields hold each point's index: Velodyne's `time` in seconds, Ouster's `t`
        // in nanoseconds, a small Livox `timestamp` as relative seconds; the dropped point's
        // time goes with it.
        for (layout, expected) in [(VELODYNE, [0.0, 2.0]), (OUSTER, [0.0, 2e-9]), (LIVOX, [0.0, 2.0])] {
            for be in [false, true] {
                let times = read_cloud(&layout_cloud(layout, &pts, be), "").unwrap().times.expect("a time field");
                assert_eq!(times, expected.map(|t: f64| t as f32).to_vec());
            }
        }
        // livox_ros_driver2: absolute nanoseconds; Hesai: absolute seconds.
        let mut msg = layout_cloud(LIVOX, &pts[..1], false);
        msg.header.stamp = rosrust::Time { sec: 1_700_000_000, nsec: 500_000_000 };
        let at = |msg: &mut sensor_msgs::PointCloud2, v: f64| msg.data[18..26].copy_from_slice(&v.to_le_bytes());
        at(&mut msg, 1_700_000_000.55e9);
        let t = read_cloud(&msg, "").unwrap().times.expect("times")[0];
        assert!((t - 0.05).abs() < 1e-6, "{t}");
        at(&mut msg, 1_700_000_000.6);
        let t = read_cloud(&msg, "").unwrap().times.expect("times")[0];
        assert!((t - 0.1).abs() < 1e-5, "{t}");
        // Our writer's `time` field reads back.
        let timed = crate::convert::cloud::write::with_times(
            cloud_msg(std_msgs::Header::default(), &[Point3::new(1.0, 2.0, 3.0); 3], Some(&[4, 5, 6]), |_| [0; 3]),
            &[0.0, 0.05, 0.1],
        );
        let scan = read_cloud(&timed, "label").unwrap();
        assert_eq!((scan.times, scan.labels), (Some(vec![0.0, 0.05, 0.1]), Some(vec![4, 5, 6])));
        // No time field: none.
        let plain = cloud_msg(std_msgs::Header::default(), &[Point3::new(1.0, 2.0, 3.0)], None, |_| [0; 3]);
        assert_eq!(read_cloud(&plain, "").unwrap().times, None);
        // A time field of the wrong type is refused, naming it.
        let mut wrong = layout_cloud(OUSTER, &pts, false);
        wrong.fields.iter_mut().filter(|f| f.name == "t").for_each(|f| f.datatype = FLOAT32);
        assert_eq!(
            read_cloud(&wrong, "").unwrap_err().to_string(),
            "field `t` has datatype 7 (float32), uint32 (nanoseconds) expected"
        );
    }

    #[test]
    fn organised_cloud_with_row_padding() {
        let mut msg = cloud_msg(std_msgs::Header::default(), &[Point3::new(1.0, 1.0, 1.0); 4], None, |_| [0; 3]);
        // 2 × 2 with 4 bytes of padding per row.
        let mut data = Vec::new();
        for row in msg.data.chunks(24) {
            data.extend_from_slice(row);
            data.extend_from_slice(&[0xAA; 4]);
        }
        (msg.width, msg.height, msg.row_step, msg.data) = (2, 2, 28, data);
        assert_eq!(read_cloud(&msg, "").unwrap().points.len(), 4);
    }

    #[test]
    fn malformed_clouds_are_refused_with_the_reason() {
        let good =
            cloud_msg(std_msgs::Header::default(), &[Point3::new(1.0, 2.0, 3.0); 3], Some(&[1, 2, 3]), |_| [0; 3]);
        let mut m = good.clone();
        m.data.truncate(50);
        assert_eq!(
            read_cloud(&m, "label").unwrap_err().to_string(),
            "data is 50 bytes, 60 expected (3 × 1 points of 20 bytes)"
        );
        let mut m = good.clone();
        m.fields[1].datatype = UINT16;
        assert_eq!(
            read_cloud(&m, "label").unwrap_err().to_string(),
            "field `y` has datatype 4 (uint16), float32 or float64 expected"
        );
        let mut m = good.clone();
        m.fields.retain(|f| f.name != "z");
        assert_eq!(read_cloud(&m, "").unwrap_err(), InputError::MissingField { field: "z".into() });
        let mut m = good.clone();
        m.fields[0].offset = 18;
        assert!(matches!(read_cloud(&m, "").unwrap_err(), InputError::FieldOutsidePoint { .. }));
        let mut m = good.clone();
        m.row_step = 10;
        assert!(read_cloud(&m, "").is_err());
        let mut m = good;
        m.fields[4].datatype = FLOAT32;
        assert!(matches!(read_cloud(&m, "label").unwrap_err(), InputError::FieldType { .. }));
    }

    proptest! {
        /// What we write reads back bit for bit: points and labels.
        #[test]
        fn written_clouds_read_back(points in proptest::collection::vec((-1e4f32..1e4, -1e4f32..1e4, -1e2f32..1e2, 0u16..400), 0..200)) {
            let pts: Vec<Point3<f32>> = points.iter().map(|p| Point3::new(p.0, p.1, p.2)).collect();
            let labels: Vec<u16> = points.iter().map(|p| p.3).collect();
            let msg = cloud_msg(std_msgs::Header::default(), &pts, Some(&labels), |l| [l as u8, 0, 0]);
            let scan = read_cloud(&msg, "label").unwrap();
            let back: Vec<Point3<f32>> = scan.points.iter().map(|p| p.map(|v| v as f32)).collect();
            prop_assert_eq!(back, pts);
            prop_assert_eq!(scan.labels, Some(labels));
        }
    }
}
