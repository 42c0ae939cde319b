//! A robot whose camera speaks a real segmenter's ids: quickstart with `classes.segmenter =
//! "ade20k_150"`, whose simulated label images carry ADE20K ids (each SGM class as the smallest
//! ADE id of its default group: chair 19, tree 4, ashcan 138, bookshelf 24 = shelf, …), confirms
//! exactly the objects of the identity run: its report is byte-identical. (Unknown ids being
//! counted: `actors/tests/classes.rs`.)

use sgm_scenarios::report;
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;
use std::path::Path;

fn quickstart(segmenter: &str) -> Scenario {
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_SEGMENTER_IDS_TEST").unwrap();
    scenario.scenario.duration_s = 40.0;
    scenario.classes.segmenter = segmenter.into();
    scenario
}

fn run_into(scenario: &Scenario, dir: &Path) -> report::Report {
    let outcome = actix_rt::System::new().block_on(run(scenario, None)).unwrap();
    report::write(&outcome, dir).unwrap()
}

#[test]
fn ade20k_ids_give_the_objects_of_the_identity_run() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let identity = run_into(&quickstart("identity"), a.path());
    let ade = run_into(&quickstart("ade20k_150"), b.path());
    let confirmed = |r: &report::Report| r.robots.iter().map(|robot| robot.confirmed_objects).collect::<Vec<_>>();
    assert!(confirmed(&identity).iter().all(|&n| n > 0), "{:?}", confirmed(&identity));
    assert_eq!(confirmed(&ade), confirmed(&identity));
    let json_a = std::fs::read(a.path().join("report.json")).unwrap();
    let json_b = std::fs::read(b.path().join("report.json")).unwrap();
    assert!(json_a == json_b, "report.json differs between the identity and the ADE20K run");
}
