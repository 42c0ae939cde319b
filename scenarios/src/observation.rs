//! What every robot knew at one time: the team's maps, neighbour states and radio counts as
//! the runner and the replay ask for them. The report, the result bag and the false-factor
//! injection read it.

use sgm_actors::comms::CommsStatus;
use sgm_actors::matcher::NeighbourStatus;
use sgm_actors::tracker::MapSummary;

/// What every robot knew at one time (`None`: not switched on yet).
#[derive(Clone, Debug, Default)]
pub struct Observation {
    pub t: f64,
    pub maps: Vec<Option<(MapSummary, Vec<NeighbourStatus>, CommsStatus)>>,
}
