//! sphere2500 (2 500 poses, 4 949 factors; `../shared/data/posegraph/3d`) with GTSAM's prior on
//! its first pose, for the pose-graph benches; `None`, said on stderr, when the data is absent.

use sgm_model::optim::g2o::{read_g2o, G2oGraph};
use sgm_model::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};

pub fn sphere2500(bench: &str) -> Option<Graph3> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/posegraph/3d/sphere2500.g2o");
    let Ok(text) = std::fs::read_to_string(&path) else {
        eprintln!("{bench}: {} not found, skipped", path.display());
        return None;
    };
    let Ok(G2oGraph::Spatial(mut graph)) = read_g2o(&[&text]) else {
        eprintln!("{bench}: {} is not a 3-D pose graph, skipped", path.display());
        return None;
    };
    graph.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
    Some(graph)
}
