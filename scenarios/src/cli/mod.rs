pub mod encode_cloud_cmd;
pub mod icp_cmd;
pub mod match_cmd;
pub mod optimize_cmd;
pub mod pcd_convert_cmd;
pub mod replay_cmd;
pub mod ros_cmd;
pub mod run_cmd;
