pub mod matching;
pub mod messages;
