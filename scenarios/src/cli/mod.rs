pub mod match_cmd;
