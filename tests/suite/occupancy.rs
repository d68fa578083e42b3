//! The grid teacher's occupancy grid: a teacher that keeps one learns the tiny scene and
//! empties the cells around the head, resumes bit for bit with the grid's state, and a
//! configuration that asks for one without a grid is refused.

use nldf_train::networks::occupancy::OccupancyConfig;
use nldf_train::trainers::config::TeacherRunConfig;
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::teacher_trainer::{TeacherModel, TeacherRun};

use crate::util::{
    assert_teacher_learns, assert_teacher_resumes_bit_for_bit, tiny_grid_run_config,
    tiny_run_config, tiny_scene,
};

/// [`tiny_grid_run_config`] with an occupancy grid of 16 cells per axis, first updated at
/// `warmup` and then every `every` steps.
fn with_occupancy(iters: usize, warmup: usize, every: usize) -> TeacherRunConfig {
    let mut cfg = tiny_grid_run_config(iters);
    cfg.model.occupancy = Some(OccupancyConfig {
        resolution: 16,
        update_every: every,
        warmup_steps: warmup,
        ..OccupancyConfig::default()
    });
    cfg
}

#[test]
fn a_grid_teacher_with_an_occupancy_grid_learns_and_empties_the_space_around_the_head() {
    assert_teacher_learns("grid teacher with occupancy", with_occupancy(200, 40, 8));
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = TeacherRun::create(dir.path(), with_occupancy(200, 40, 8), &data).unwrap();
    let occ = run.model.teacher.occupancy.clone().unwrap();
    assert_eq!(
        occ.mask().unwrap().fraction(),
        1.0,
        "unmeasured cells count as occupied"
    );
    for _ in 0..200 {
        run.train_step(&data).unwrap();
    }
    let fraction = occ.mask().unwrap().fraction();
    eprintln!(
        "occupied after 200 steps: {:.1} % of the cells",
        100.0 * fraction
    );
    // The tiny field is young: its empty space is only starting to fall below the
    // threshold, but some cells have (a grid that never updated stays all occupied).
    assert!(fraction > 0.01 && fraction < 0.99, "occupied: {fraction}");
    // The grid travels with the weights: a model opened to render sees the same cells.
    run.save().unwrap();
    let model = TeacherModel::open(dir.path()).unwrap();
    let reopened = model.teacher.occupancy.as_ref().unwrap().mask().unwrap();
    assert_eq!(reopened, occ.mask().unwrap());
}

/// The occupancy grid's cell densities of a run, as bits.
fn density_bits(run: &TeacherRun) -> Vec<u32> {
    let occ = run.model.teacher.occupancy.as_ref().unwrap();
    let values: Vec<f32> = occ.density.as_tensor().to_vec1().unwrap();
    values.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn a_resumed_grid_teacher_with_an_occupancy_grid_continues_bit_for_bit() {
    // Updated at every step from step 2: the grid's state at the save decides the next steps.
    assert_teacher_resumes_bit_for_bit(with_occupancy(20, 2, 1));
    // The cells themselves: saved, restored and updated alike.
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = TeacherRun::create(dir.path(), with_occupancy(20, 2, 1), &data).unwrap();
    for _ in 0..6 {
        run.train_step(&data).unwrap();
    }
    run.save().unwrap();
    let saved = density_bits(&run);
    run.train_step(&data).unwrap();
    run.train_step(&data).unwrap();
    let mut resumed = TeacherRun::open(dir.path()).unwrap();
    assert_eq!(density_bits(&resumed), saved);
    resumed.train_step(&data).unwrap();
    resumed.train_step(&data).unwrap();
    assert_eq!(density_bits(&resumed), density_bits(&run));
}

#[test]
fn an_occupancy_grid_without_the_grid_teacher_is_refused() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = tiny_run_config(10);
    cfg.model.occupancy = Some(OccupancyConfig::default());
    let err = TeacherRun::create(dir.path(), cfg, &data)
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("model.occupancy"), "{err}");
    let mut bad = with_occupancy(10, 0, 1);
    bad.model.occupancy.as_mut().unwrap().resolution = 100_000;
    assert!(TeacherRun::create(dir.path(), bad, &data).is_err());
}
