//! [`GraphFactors`] to and from a slice of a pose graph's factor log
//! ([`crate::optim::shared_factors`]). What comes from outside is checked here, once: a pose
//! that is not finite, an up that is not a unit vector, an information matrix that is not
//! symmetric positive definite — each such part is left out and counted.

use super::messages::{GraphFactors, WireFactor, WireFactorKind, WireGraphKeyframe, WireInformation, WireKeyframePose};
use crate::geometry::up::unit_up;
use crate::optim::shared_factors::{LogSlice, SharedFactor, SharedKeyframe, SharedKind};
use nalgebra::{Matrix6, Vector3};

impl GraphFactors {
    /// Ups travel in single precision: a unit vector stays within 1e-7 of unit length.
    pub fn from_slice(slice: &LogSlice) -> Self {
        let keyframes = slice
            .keyframes
            .iter()
            .map(|k| WireGraphKeyframe {
                pose: WireKeyframePose::new(k.keyframe, &k.pose),
                up: k.up.map(|u| [u.x as f32, u.y as f32, u.z as f32]),
            })
            .collect();
        let mut previous = None;
        let factors = slice
            .factors
            .iter()
            .map(|f| {
                let kind = match f.kind {
                    SharedKind::Odometry => WireFactorKind::Odometry,
                    SharedKind::Loop => WireFactorKind::Loop,
                    SharedKind::InterRobot => WireFactorKind::InterRobot,
                };
                let information = WireInformation::pack(&f.information, previous);
                previous = Some(&f.information);
                WireFactor::new(kind, f.from, f.to, &f.measured, information)
            })
            .collect();
        Self { from: slice.from, next: slice.next, keyframes, factors }
    }

    /// The slice, and how many of its parts were malformed and left out (a keyframe whose
    /// up alone is malformed stays, without its up).
    pub fn to_slice(&self) -> (LogSlice, usize) {
        let mut malformed = 0;
        let mut keyframes = Vec::with_capacity(self.keyframes.len());
        for k in &self.keyframes {
            let Some(pose) = k.pose.to_pose() else {
                malformed += 1;
                continue;
            };
            let up = k.up.map(|[x, y, z]| Vector3::new(f64::from(x), f64::from(y), f64::from(z)).normalize());
            let up = match up {
                Some(u) if !unit_up(&u) => {
                    malformed += 1;
                    None
                }
                up => up,
            };
            keyframes.push(SharedKeyframe { keyframe: k.pose.keyframe, pose, up });
        }
        let mut factors = Vec::with_capacity(self.factors.len());
        // The previous factor's information as sent (a `Previous` after a malformed one is
        // malformed too).
        let mut previous: Option<Matrix6<f64>> = None;
        for f in &self.factors {
            let information = f.information.unpack(previous.as_ref());
            previous = information;
            let (Some(measured), Some(information)) = (f.measured(), information) else {
                malformed += 1;
                continue;
            };
            let kind = match f.kind {
                WireFactorKind::Odometry => SharedKind::Odometry,
                WireFactorKind::Loop => SharedKind::Loop,
                WireFactorKind::InterRobot => SharedKind::InterRobot,
            };
            factors.push(SharedFactor { kind, from: f.from, to: f.to, measured, information });
        }
        (LogSlice { from: self.from, next: self.next, keyframes, factors }, malformed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_rpy_translation, Pose3};
    use crate::scene_graph::KeyframeId;

    fn slice() -> LogSlice {
        let information = Matrix6::from_fn(|i, j| if i == j { 1e4 } else { 0.5 });
        LogSlice {
            from: 3,
            next: 9,
            keyframes: vec![SharedKeyframe {
                keyframe: KeyframeId(4),
                pose: pose_from_rpy_translation(0.01, -0.02, 1.2, Vector3::new(120.5, -3.25, 1.5)),
                up: Some(Vector3::new(0.01, -0.02, 1.0).normalize()),
            }],
            factors: vec![SharedFactor {
                kind: SharedKind::InterRobot,
                from: KeyframeId(4),
                to: KeyframeId(70),
                measured: pose_from_rpy_translation(0.0, 0.0, -0.4, Vector3::new(2.0, 1.0, 0.0)),
                information,
            }],
        }
    }

    #[test]
    fn a_slice_round_trips_in_single_precision() {
        let sent = slice();
        let wire = GraphFactors::from_slice(&sent);
        let (back, malformed) = wire.to_slice();
        assert_eq!(malformed, 0);
        assert_eq!((back.from, back.next), (3, 9));
        let close = |a: &Pose3, b: &Pose3| {
            (a.translation.vector - b.translation.vector).norm() < 1e-4 && a.rotation.angle_to(&b.rotation) < 1e-6
        };
        assert!(close(&back.keyframes[0].pose, &sent.keyframes[0].pose));
        assert!((back.keyframes[0].up.unwrap() - sent.keyframes[0].up.unwrap()).norm() < 1e-6);
        assert!(close(&back.factors[0].measured, &sent.factors[0].measured));
        assert_eq!(back.factors[0].kind, SharedKind::InterRobot);
        assert!(((back.factors[0].information - sent.factors[0].information).norm() / 1e4) < 1e-6);
        let bytes = postcard::to_allocvec(&wire).unwrap();
        assert!(bytes.len() < 180, "{} bytes for a keyframe and a factor", bytes.len());
    }

    /// Odometry's diagonal information costs 25 bytes, then a byte for each factor that repeats
    /// it; a full one 85; each comes back as it went.
    #[test]
    fn informations_are_packed_as_compactly_as_they_go() {
        let mut slice = slice();
        let diagonal = Matrix6::from_diagonal(&nalgebra::Vector6::new(1e4, 1e4, 1e4, 400.0, 400.0, 400.0));
        let full = slice.factors[0].information;
        let factor = slice.factors[0];
        slice.factors = vec![
            SharedFactor { information: diagonal, ..factor },
            SharedFactor { information: diagonal, ..factor },
            SharedFactor { information: full, ..factor },
        ];
        let wire = GraphFactors::from_slice(&slice);
        let size = |i: usize| postcard::to_allocvec(&wire.factors[i].information).unwrap().len();
        assert!(matches!(wire.factors[0].information, WireInformation::Diagonal(_)));
        assert_eq!(wire.factors[1].information, WireInformation::Previous);
        assert!(matches!(wire.factors[2].information, WireInformation::Full(_)));
        assert_eq!((size(0), size(1), size(2)), (25, 1, 85));
        let (back, malformed) = wire.to_slice();
        assert_eq!(malformed, 0);
        for (b, s) in back.factors.iter().zip(&slice.factors) {
            assert!((b.information - s.information).norm() / s.information.norm() < 1e-6);
        }
    }

    #[test]
    fn malformed_parts_are_left_out_and_counted() {
        let mut wire = GraphFactors::from_slice(&slice());
        wire.keyframes.push(WireGraphKeyframe {
            pose: WireKeyframePose { keyframe: KeyframeId(5), translation: [f32::NAN, 0.0, 0.0], rotation: [0.0; 3] },
            up: None,
        });
        let mut keyframe = wire.keyframes[0];
        keyframe.up = Some([0.0, 0.0, 0.0]);
        wire.keyframes.push(keyframe);
        let mut factor = wire.factors[0];
        factor.information = WireInformation::Full([0.0; 21]);
        wire.factors.push(factor);
        factor.information = WireInformation::Previous;
        wire.factors.push(factor);
        factor.information = WireInformation::Diagonal([1.0, 1.0, -1.0, 1.0, 1.0, 1.0]);
        wire.factors.push(factor);
        let (back, malformed) = wire.to_slice();
        assert_eq!(malformed, 5, "a NaN pose, a zero up, a zero information, the one after it, an indefinite one");
        assert_eq!(back.keyframes.len(), 2, "the keyframe with a bad up stays, without it");
        assert_eq!(back.keyframes[1].up, None);
        assert_eq!(back.factors.len(), 1);
    }
}
