//! `sgm doctor --bag FILE`: a robot's recorded inputs through the doctor, as `sgm replay`
//! would read them (the same reader, checks and synchroniser).

use super::{Doctor, DoctorError, DoctorReport};
use crate::bag::reader::{read_bag, BagItem, BagSource};
use crate::inputs::Payload;
use crate::node::NodeConfig;
use sgm_actors::config::OdometrySource;
use std::path::Path;

/// Examines robot `config`'s inputs in the bag at `path`.
pub fn examine_bag(path: &Path, config: &NodeConfig) -> Result<DoctorReport, DoctorError> {
    let mut doctor = Doctor::new(config)?;
    let colours = config.robot.colour_ids()?;
    let mut source = BagSource::new(&config.ros, &config.robot.robot.name, config.robot.robot.id).with_colours(colours);
    if doctor.source() == OdometrySource::Internal {
        source = source.with_imu();
    }
    for item in read_bag(path, source) {
        match item {
            BagItem::Message { payload: Payload::GroundTruth(..), .. } => {}
            BagItem::Message { payload, .. } => doctor.observe(payload.input_name(), Ok(payload)),
            BagItem::Refused { input, error, .. } => doctor.observe(input, Err(error)),
            BagItem::Failed(e) => return Err(DoctorError::Bag(e)),
        }
    }
    Ok(doctor.finish(format!("bag {}", path.display()), true))
}
