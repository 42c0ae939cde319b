//! People walking through a run (`segmentation.people`): the LiDAR sees them, the segmenter
//! labels them `person`, and because that class is dynamic no robot maps one, while the static
//! objects are mapped as well as without people. The same run with `person` not dynamic maps
//! people: the flag, not chance, keeps them out.

use sgm_model::scene_graph::{LabelId, SceneGraph};
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;

/// Quickstart cut to 60 s (the robots set off at 2 s and slow for corners), with `people` walking.
fn scenario(people: usize) -> Scenario {
    let text = sgm_scenarios::scenario::library::get("quickstart").expect("in the library");
    let text = text.replace("duration_s = 90.0", "duration_s = 60.0");
    let text = format!("{text}\n[segmentation]\npeople = {people}\n");
    Scenario::from_toml(&text, "people.toml", "SGM_PEOPLE_TEST").expect("loads")
}

fn maps(scenario: &Scenario) -> Vec<SceneGraph> {
    actix_rt::System::new().block_on(run(scenario, None)).expect("runs").maps
}

fn count(maps: &[SceneGraph], keep: impl Fn(LabelId) -> bool) -> usize {
    maps.iter().map(|m| m.objects().filter(|o| keep(o.label)).count()).sum()
}

#[test]
fn people_never_become_map_objects_and_the_static_objects_still_do() {
    let with_people = scenario(12);
    let person = with_people.fusion.classes.iter().find(|c| c.name == "person").expect("added for the people");
    assert!(person.dynamic);
    let person = LabelId(person.id);

    let static_alone = count(&maps(&scenario(0)), |_| true);
    let mapped = maps(&with_people);
    assert_eq!(count(&mapped, |l| l == person), 0, "no person is a map object");
    let static_with_people = count(&mapped, |l| l != person);
    assert!(
        static_with_people * 10 >= static_alone * 9,
        "static objects: {static_with_people} with people, {static_alone} without"
    );

    // The same people, their class not dynamic: the robots see them and map them.
    let mut careless = with_people.clone();
    careless.fusion.classes.iter_mut().filter(|c| c.name == "person").for_each(|c| c.dynamic = false);
    let people_mapped = count(&maps(&careless), |l| l == person);
    assert!(people_mapped > 0, "people seen by the LiDAR and segmented become objects when not dynamic");
}
