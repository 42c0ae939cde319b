pub mod match_cmd;
pub mod optimize_cmd;
