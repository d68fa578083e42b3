//! Training and inference take a frame's inputs from one home: for frames of the tiny scene,
//! the rays the student trainer builds and the rays the renderer sends through the network
//! are the same rays through the same pixels, and the audio neighbourhood the trainer
//! encodes is the one the renderer makes from the scene's WAV, bit for bit.

use crate::util::tiny_scene;
use nldf_core::audio::neighbourhood;
use nldf_core::dataset::Split;
use nldf_export::{WeightType, export_student};
use nldf_infer::audio::windows_from_wav;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_infer::frame::FrameRenderer;
use nldf_model::read_model;
use nldf_train::networks::student::StudentConfig;
use nldf_train::trainers::config::StudentRunConfig;
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::student_trainer::StudentRun;
use nldf_train::trainers::views::{frame_beams, training_views};

#[test]
fn the_trainer_and_the_renderer_build_the_same_inputs_for_a_frame() {
    let scene = tiny_scene();
    let data = TrainData::load(scene).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = StudentRunConfig {
        model: StudentConfig::tiny(),
        ..StudentRunConfig::default()
    };
    cfg.train.distill = false;
    let student_dir = dir.path().join("student");
    let mut run = StudentRun::create(&student_dir, cfg, &data, None).unwrap();
    run.prepare(&data, None, &mut |_, _| {}).unwrap();
    run.save().unwrap();
    let model = dir.path().join("model.onnx");
    export_student(&student_dir, &model, WeightType::F32).unwrap();
    let exported = read_model(&model).unwrap();
    let info = exported.info.clone();
    let backend = backend_for(
        &exported,
        BackendKind::Tract,
        BackendOptions {
            batch_size: 256,
            threads: 1,
            spin: true,
        },
    )
    .unwrap();
    let renderer = FrameRenderer::new(backend, None).unwrap();

    let views = training_views(&data, &run.model.cfg.train);
    let beams = frame_beams(&data, &views, None);
    let frames = data.dataset.frames(Split::Train);
    let width = data.dataset.intrinsics.width as usize;
    let wav_windows = windows_from_wav(&info, &model, &scene.join("aud.wav")).unwrap();
    let att = run.model.cfg.model.audio.att_frames;
    for fi in [0, frames.len() / 2, frames.len() - 1] {
        // Rays: the trainer's hit pixels and their rays against the renderer's.
        let view = &views[fi];
        let rendered = renderer.rays(view.camera.c2w);
        let pixels: Vec<usize> = beams[fi]
            .pixels
            .iter()
            .map(|&(i, j)| j as usize * width + i as usize)
            .collect();
        assert!(!pixels.is_empty(), "frame {fi} sees no head");
        assert_eq!(pixels, rendered.pixels, "frame {fi}: pixels differ");
        for (r, &(i, j)) in beams[fi].pixels.iter().enumerate() {
            let (o, d) = view.camera.ray(i as f32, j as f32);
            assert_eq!(o, rendered.rays.origin(r), "frame {fi} ray {r}: origin");
            assert_eq!(
                d,
                rendered.rays.direction(r),
                "frame {fi} ray {r}: direction"
            );
        }
        // Audio: the trainer's neighbourhood tensor against the renderer's from the WAV.
        let aud_id = frames[fi].aud_id;
        let trained: Vec<f32> = data
            .neighbourhoods(&[aud_id], att)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let rendered_audio = neighbourhood(&wav_windows, aud_id, att);
        assert_eq!(trained.len(), rendered_audio.len());
        assert!(
            trained
                .iter()
                .zip(&rendered_audio)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "frame {fi}: audio neighbourhoods differ"
        );
    }
}
