//! The doctor's answer: a verdict per input and for the robot, and the report as the terminal
//! shows it.

use crate::health::Finding;
use serde::Serialize;

/// How an input (or the whole robot) fares.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Verdict {
    Ok,
    Warn,
    Fail,
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Verdict::Ok => "OK",
            Verdict::Warn => "WARN",
            Verdict::Fail => "FAIL",
        })
    }
}

/// One input's (or check's) verdict: what was seen, and what is wrong.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InputVerdict {
    pub input: String,
    pub verdict: Verdict,
    pub seen: String,
    pub problems: Vec<String>,
}

/// The doctor's whole answer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DoctorReport {
    pub robot: String,
    /// The bag, or the master and how long it was listened to.
    pub source: String,
    /// From the first to the last sensor stamp, s.
    pub span_s: f64,
    pub inputs: Vec<InputVerdict>,
    /// The node's health findings over the whole span (each is quoted in its input's problems).
    pub findings: Vec<Finding>,
    pub verdict: Verdict,
}

impl DoctorReport {
    /// The report as the terminal shows it.
    pub fn text(&self) -> String {
        let mut out = format!("sgm doctor: robot {}, {} ({:.1} s of stamps)\n", self.robot, self.source, self.span_s);
        for v in &self.inputs {
            out.push_str(&format!("  {:<12} {:<4}  {}\n", v.input, v.verdict.to_string(), v.seen));
            for p in &v.problems {
                out.push_str(&format!("  {:<12}       - {p}\n", ""));
            }
        }
        let count = |v: Verdict| self.inputs.iter().filter(|i| i.verdict == v).count();
        out.push_str(&format!(
            "verdict: {} ({} failed, {} with warnings, {} ok)\n",
            self.verdict,
            count(Verdict::Fail),
            count(Verdict::Warn),
            count(Verdict::Ok)
        ));
        out
    }
}
