//! The page (`web/`) in Debian's headless Chromium against nldf: the frames it draws on its
//! canvas with onnxruntime-web (WASM, SIMD, 2 threads) from the shipped frame graph and a
//! WAV picked through its file input are nldf's frames (`FrameRenderer` on the shipped ray
//! graph) within 1/255 per channel, at both ends and the middle of the track, from the
//! default pose and a turned one, with still-pixel skipping off; with it on, over the WAV at
//! the default pose, the page makes its full, probed and partial frames where nldf's
//! `StillSkipper` (`nldf render --skip-still`) makes them, a skipped frame's re-rendered
//! pixels are nldf's full frame's within 1/255 and its others the page's last full frame's
//! exactly, and the skipped frames stray from nldf's full frames no further than nldf's own
//! skipping does on the same clip (worst channel within 1/255 of nldf's worst, PSNR within
//! 0.5 dB); the microphone (Chromium's fake device playing the WAV)
//! gives a chunk that is not silent and a frame within 1/255 of the Rust frame graph's for that
//! chunk; a ray graph picked instead is refused on the page; and the page reports no error.
//! Needs node, /usr/bin/chromium and web/node_modules (`scripts/web_env.sh`): outside CI a
//! missing one skips, under CI it fails. The page's WAV reader is also run in node alone
//! against nldf's: it refuses NaN and infinite samples with nldf's line.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::Mat4;
use nldf_core::audio::neighbourhood;
use nldf_core::camera::turn_about;
use nldf_infer::FrameRenderer;
use nldf_infer::audio::windows_from_wav;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_infer::frame_graph::FrameGraph;
use nldf_infer::still::{FrameKind, SkipConfig, StillSkipper, probe_frames};
use nldf_model::{read_frame_model, read_model};

use crate::util::{ort_available, write_test_wav};

/// Worst allowed difference of an 8-bit channel between the page's canvas and nldf. Both
/// round the same float colours to 8 bits the same way, so a float difference under one
/// step shows as at most one step.
const TOL_8BIT: u8 = 1;

/// The turned pose: yaw, pitch in radians.
const POSES: [(f32, f32); 2] = [(0.0, 0.0), (0.35, -0.15)];

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Whether node runs here.
fn node_runs() -> bool {
    Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

const NODE_MISSING: &str = "node is missing (install Node.js 18 or newer)";

/// Whether node, Chromium and the page's npm packages are here; outside CI a missing one
/// skips (after saying so), under CI it fails.
fn browser_available() -> bool {
    let web = repo().join("web");
    let missing = if !node_runs() {
        Some(NODE_MISSING.to_string())
    } else if !Path::new("/usr/bin/chromium").exists() {
        Some("/usr/bin/chromium is missing: run scripts/web_env.sh".to_string())
    } else if !web.join("node_modules/onnxruntime-web/dist").is_dir()
        || !web.join("node_modules/playwright-core").is_dir()
    {
        Some("web/node_modules is missing: run scripts/web_env.sh".to_string())
    } else {
        None
    };
    match missing {
        None => true,
        Some(msg) => nldf_tests::tool_missing::<()>(msg).is_some(),
    }
}

/// The page's modules in node, without a browser: its unit tests (`web/test/*.test.mjs`: the
/// WAV reader, the WebAssembly SIMD detection) pass, and float WAVs holding a NaN or an infinity (mono and
/// stereo, in the first, a middle and the last frame) are refused with nldf's own line,
/// `read_wav`'s error word for word, while a finite one is read to as many samples as
/// nldf reads. Needs node only: outside CI a missing node skips, under CI it fails.
#[test]
fn the_pages_wav_reader_refuses_what_nldf_refuses() {
    if !node_runs() {
        nldf_tests::tool_missing::<()>(NODE_MISSING);
        return;
    }
    let run = |args: &[&str]| {
        let out = Command::new("node")
            .current_dir(repo())
            .args(args)
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "node {args:?} failed:\n{text}");
        text
    };
    let mut units: Vec<String> = std::fs::read_dir(repo().join("web/test"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".test.mjs"))
        .map(|name| format!("web/test/{name}"))
        .collect();
    units.sort();
    for unit in ["web/test/audio.test.mjs", "web/test/wasm.test.mjs"] {
        assert!(units.iter().any(|u| u == unit), "{unit} is missing");
    }
    let mut args = vec!["--test", "--test-reporter=tap"];
    args.extend(units.iter().map(String::as_str));
    let said = run(&args);
    assert!(said.contains("# fail 0"), "node's tests:\n{said}");

    let tmp = tempfile::tempdir().unwrap();
    let write = |name: &str, channels: u16, samples: &[f32]| {
        let path = tmp.path().join(name);
        let spec = hound::WavSpec {
            channels,
            sample_rate: 16_000,
            bits_per_sample: 32,
            sample_format: hound::SampleFormat::Float,
        };
        let mut w = hound::WavWriter::create(&path, spec).unwrap();
        for &v in samples {
            w.write_sample(v).unwrap();
        }
        w.finalize().unwrap();
        path
    };
    let files = [
        write("nan_middle.wav", 1, &[0.1, 0.2, f32::NAN, 0.3]),
        write("inf_first.wav", 1, &[f32::INFINITY, 0.2]),
        write(
            "neg_inf_last_stereo.wav",
            2,
            &[0.1, 0.1, 0.2, f32::NEG_INFINITY],
        ),
        write("finite.wav", 2, &[0.5, -0.5, 0.25, 0.125, 1.0, -1.0]),
    ];
    let names: Vec<&str> = files.iter().map(|f| f.to_str().unwrap()).collect();
    let script = "import { readFileSync } from 'node:fs';
        import { parseWav } from './web/src/audio.js';
        for (const file of process.argv.slice(1)) {
          try {
            const wav = parseWav(new Uint8Array(readFileSync(file)), file);
            console.log(JSON.stringify({ samples: wav ? wav.samples.length : null }));
          } catch (e) {
            console.log(JSON.stringify({ error: e.message }));
          }
        }";
    let mut args = vec!["--input-type=module", "-e", script];
    args.extend(&names);
    let said = run(&args);
    let lines: Vec<serde_json::Value> = said
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), files.len(), "one line per file:\n{said}");
    for (file, page) in files.iter().zip(&lines) {
        match nldf_core::audio::read_wav(file) {
            Err(e) => assert_eq!(
                page["error"].as_str(),
                Some(e.to_string().as_str()),
                "{}: the page's line against nldf's",
                file.display()
            ),
            Ok(wave) => assert_eq!(
                page["samples"].as_u64(),
                Some(wave.samples.len() as u64),
                "{}: read by nldf, the page says {page}",
                file.display()
            ),
        }
        println!("{}: {page}", file.file_name().unwrap().to_string_lossy());
    }
    let refused = lines.iter().filter(|l| l["error"].is_string()).count();
    assert_eq!(refused, 3, "nldf refuses the three non-finite files");
}

/// The largest difference between two 8-bit images, and how many channels differ at all.
fn diff_8bit(a: &[u8], b: &[u8]) -> (u8, usize) {
    assert_eq!(a.len(), b.len(), "image sizes");
    a.iter().zip(b).fold((0, 0), |(worst, n), (x, y)| {
        let d = x.abs_diff(*y);
        (worst.max(d), n + usize::from(d > 0))
    })
}

fn read_f32(path: &Path) -> Vec<f32> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

#[test]
fn the_page_draws_nldf_frames_from_a_wav_and_the_microphone() {
    if !browser_available() {
        return;
    }
    let root = repo();
    let tmp = tempfile::tempdir().unwrap();
    let wav = tmp.path().join("speech.wav");
    write_test_wav(&wav, 2.0);
    let out = tmp.path().join("browser");

    let ray_path = root.join("models/demo/model.onnx");
    let model = read_model(&ray_path).unwrap();
    let info = &model.info;
    let windows = windows_from_wav(info, &ray_path, &wav).unwrap();
    let n = windows.n_frames;
    let frames = [0, 1, n / 2, n - 2, n - 1];
    let default_pose = Mat4::from_cols_array_2d(&info.spec.default_pose).transpose();
    let centre = info.spec.bounds.centre();
    let pose = |(yaw, pitch): (f32, f32)| turn_about(centre, yaw, pitch) * default_pose;

    let n_skip = n.to_string();
    let ray_graph = ray_path.to_str().unwrap();
    let result = run_page(
        &wav,
        &out,
        &frames,
        &["--skip-frames", &n_skip, "--ray-graph", ray_graph, "--mic"],
    );
    println!(
        "{}, onnxruntime-web {}, {} threads, SIMD {}, cross-origin isolated: {}",
        result["chromium"],
        result["ort_version"],
        result["threads"],
        result["simd"],
        result["crossOriginIsolated"]
    );

    assert_eq!(result["crossOriginIsolated"], true, "COOP/COEP headers");
    assert_eq!(
        result["simd"], true,
        "the page detects Chromium's WASM SIMD"
    );
    assert!(result["threads"].as_u64().unwrap() >= 2, "threads");
    let refused = result["ray_graph_error"].as_str().unwrap_or_default();
    assert!(
        refused.contains("ray graph") && refused.contains("--frame"),
        "a ray graph was not refused with a clear line: {refused:?}"
    );
    assert_eq!(
        result["ray_graph_error_shown"], true,
        "the error is on the page"
    );
    assert_eq!(result["track"]["frames"].as_u64(), Some(n as u64));
    let drag = &result["drag"];
    assert!(
        drag["yaw_deg"].as_f64().unwrap() < -1.0 && drag["pitch_deg"].as_f64().unwrap() > 0.5,
        "dragging right and up turns the head: {drag}"
    );
    let (w, h) = (
        info.spec.intrinsics.width as usize,
        info.spec.intrinsics.height as usize,
    );
    assert_eq!(
        (result["width"].as_u64(), result["height"].as_u64()),
        (Some(w as u64), Some(h as u64))
    );

    // The WAV picked through the file input: nldf's frames.
    let mut renderer = tract_renderer(&model);
    let parity = check_frames(&result, &out, &mut renderer, &windows, &pose);
    assert_eq!(
        result["frames"].as_array().unwrap().len(),
        frames.len() * POSES.len()
    );
    println!(
        "{} canvas frames against nldf render: {parity}",
        frames.len() * POSES.len()
    );

    check_skipping(&result, &out, &model, &windows, &mut renderer);

    // The microphone: a chunk that is not silent, and the Rust frame graph's frame for it.
    let frame_model = read_frame_model(&root.join("models/demo/frame.onnx")).unwrap();
    let chunk = read_f32(&out.join(result["mic"]["chunk"].as_str().unwrap()));
    assert_eq!(
        chunk.len(),
        frame_model.audio.samples,
        "the microphone chunk"
    );
    // The newest samples end where the graph stops reading (the shipped student has no
    // attention: its own window, 152.5 ms past the frame's instant), NaN after.
    let info = &frame_model.info.audio;
    let read_end = frame_model.audio.read_end(info.attention, info.ahead);
    assert!(read_end < chunk.len(), "{read_end} of {}", chunk.len());
    assert!(
        chunk[read_end..].iter().all(|v| v.is_nan()),
        "the microphone chunk holds samples past the graph's read end {read_end}"
    );
    let live: Vec<f32> = chunk.iter().copied().filter(|v| !v.is_nan()).collect();
    let rms = (live.iter().map(|v| v * v).sum::<f32>() / live.len().max(1) as f32).sqrt();
    assert!(
        live.len() == read_end && rms > 0.05,
        "the microphone chunk is silent or short: rms {rms}, {} of {read_end} samples",
        live.len(),
    );
    let kind = if ort_available() {
        BackendKind::Ort
    } else {
        BackendKind::Tract
    };
    let mut graph = FrameGraph::open(&frame_model, kind, 2).unwrap();
    let yaw = result["mic"]["yaw"].as_f64().unwrap() as f32;
    let pitch = result["mic"]["pitch"].as_f64().unwrap() as f32;
    let want = graph
        .render(pose((yaw, pitch)), &chunk)
        .unwrap()
        .image
        .to_rgb8();
    let got = std::fs::read(out.join(result["mic"]["file"].as_str().unwrap())).unwrap();
    let (d, changed) = diff_8bit(&got, &want);
    println!(
        "microphone: rms {rms:.3}, canvas against the frame graph in {}: {d}/255",
        kind.name()
    );
    assert!(
        d <= TOL_8BIT,
        "microphone: the canvas is {d}/255 off the frame graph's frame ({changed} channels differ)"
    );
}

/// PSNR of 8-bit images' summed squared error over `values` channels; infinite for 0.
fn psnr_8bit(sq: f64, values: usize) -> f64 {
    let mse = sq / values.max(1) as f64 / (255.0 * 255.0);
    if mse > 0.0 {
        -10.0 * mse.log10()
    } else {
        f64::INFINITY
    }
}

/// The page's frames with skipping on (`result["skip"]`: the track's frames in order at the
/// default pose from a fresh skipper) against nldf's full frames (`renderer`) and nldf's
/// own skipping on the same clip.
fn check_skipping(
    result: &serde_json::Value,
    out: &Path,
    model: &nldf_model::ExportedModel,
    windows: &nldf_core::audio::AudioWindows,
    renderer: &mut FrameRenderer,
) {
    let info = &model.info;
    let att = info.audio.att_frames;
    let pose = Mat4::from_cols_array_2d(&info.spec.default_pose).transpose();
    let config = SkipConfig::default();
    let probes = probe_frames(windows.n_frames, config.probes)
        .into_iter()
        .map(|f| neighbourhood(windows, f, att))
        .collect();
    let mut skipper = StillSkipper::new(config, probes).unwrap();
    let options = BackendOptions {
        batch_size: 4096,
        threads: 2,
        spin: true,
    };
    let backend = backend_for(model, BackendKind::Tract, options).unwrap();
    let mut skipping = FrameRenderer::new(backend, None).unwrap();
    let frames = result["skip"]
        .as_array()
        .expect("the page's skipping frames");
    assert_eq!(frames.len(), windows.n_frames, "skipping frames");
    let mut last_full: Option<Vec<u8>> = None;
    let (mut worst_kept, mut skipped, mut values) = (0u8, 0usize, 0usize);
    let (mut page_sq, mut page_worst, mut nldf_sq, mut nldf_worst) = (0f64, 0u8, 0f64, 0u8);
    let (mut page_rays, mut nldf_rays, mut patch_rays) = (0usize, 0usize, 0usize);
    for (f, entry) in frames.iter().enumerate() {
        let audio = neighbourhood(windows, f, att);
        let whole = renderer.render(pose, &audio).unwrap();
        let full = whole.image.to_rgb8();
        let nldf = skipper.render(&mut skipping, pose, &audio).unwrap();
        let kind = entry["kind"].as_str().unwrap_or_default();
        let want_kind = match nldf.kind {
            FrameKind::Full => "full",
            FrameKind::Probed => "probed",
            FrameKind::Partial => "partial",
        };
        assert_eq!(kind, want_kind, "frame {f}: how the page made it");
        let got = std::fs::read(out.join(entry["file"].as_str().unwrap())).unwrap();
        assert_eq!(got.len(), full.len(), "frame {f}: canvas size");
        if kind == "full" {
            let (d, _) = diff_8bit(&got, &full);
            assert!(d <= TOL_8BIT, "frame {f}: a full frame {d}/255 off nldf's");
            last_full = Some(got.clone());
        } else {
            let keep = std::fs::read(out.join(entry["keep"].as_str().unwrap())).unwrap();
            assert_eq!(keep.len() * 3, got.len(), "frame {f}: mask size");
            let base = last_full
                .as_ref()
                .expect("a full frame before a skipped one");
            for (p, &k) in keep.iter().enumerate() {
                let px = 3 * p..3 * p + 3;
                if k != 0 {
                    worst_kept = worst_kept.max(diff_8bit(&got[px.clone()], &full[px]).0);
                } else {
                    assert_eq!(
                        got[px.clone()],
                        base[px],
                        "frame {f}: pixel {p} is not re-rendered but differs from the page's \
                         last full frame"
                    );
                }
            }
            skipped += 1;
            page_rays += entry["n_rays"].as_u64().unwrap() as usize;
            // The frame graph draws the whole mouth patch whatever `keep` says; nldf sends
            // the patch's rays of the moving pixels only. The coarse rays are the same.
            nldf_rays += nldf.frame.head_pixels - nldf.frame.patch_pixels + whole.patch_pixels;
            patch_rays += whole.patch_pixels;
        }
        let nldf_rgb8 = nldf.frame.image.to_rgb8();
        for (x, (a, b)) in got.iter().zip(&nldf_rgb8).enumerate() {
            let (dp, dn) = (a.abs_diff(full[x]), b.abs_diff(full[x]));
            page_sq += (dp as f64).powi(2);
            nldf_sq += (dn as f64).powi(2);
            page_worst = page_worst.max(dp);
            nldf_worst = nldf_worst.max(dn);
        }
        values += full.len();
    }
    let (page_psnr, nldf_psnr) = (psnr_8bit(page_sq, values), psnr_8bit(nldf_sq, values));
    println!(
        "skipping, {} frames ({skipped} skipped; re-rendered rays {page_rays} on the page, \
         {nldf_rays} in nldf, each with the whole mouth patch, {patch_rays} rays): \
         re-rendered pixels against nldf's full frames {worst_kept}/255; \
         against the full frames, page {page_psnr:.2} dB (worst {page_worst}/255), nldf's \
         --skip-still {nldf_psnr:.2} dB (worst {nldf_worst}/255)",
        frames.len()
    );
    assert!(
        skipped >= frames.len() / 2,
        "the page skipped {skipped} frames"
    );
    // The audio moves some of the head, and the page sends the graph the rays nldf sends.
    assert!(page_rays > 0, "no skipped frame re-rendered a ray");
    assert_eq!(
        page_rays, nldf_rays,
        "rays re-rendered, the page's and nldf's"
    );
    assert!(
        worst_kept <= TOL_8BIT,
        "re-rendered pixels {worst_kept}/255 off nldf's full frames"
    );
    assert!(
        page_worst <= nldf_worst + TOL_8BIT && page_psnr >= nldf_psnr - 0.5,
        "the page's skipping strays further from the full frames than nldf's: \
         {page_psnr:.2} dB (worst {page_worst}/255) against {nldf_psnr:.2} dB \
         (worst {nldf_worst}/255)"
    );
}

/// A frame graph with a learned upsampler (the real-time student at 128 x 128, x4, weights
/// at a trained network's magnitude) picked through the page's file input: the page sizes
/// `keep` to the coarse grid, says so, and draws nldf's frames (`FrameRenderer` on the same
/// student and upsampler's ray graph) within 1/255, at both ends and the middle of the
/// track, from the default pose and a turned one. With still-pixel skipping on, the page
/// gives the graph the coarse cells its kept pixels read, and its frames match nldf's own
/// skipping on the upsampled ray graph (`check_skipping`).
#[test]
fn the_page_draws_an_upsampled_frame_graph() {
    if !browser_available() {
        return;
    }
    use nldf_core::student_config::StudentConfig;
    use nldf_core::upsampler_config::UpsamplerConfig;
    use nldf_export::{WeightType, export_frame, export_frame_upsampled, export_student_upsampled};

    let mut cfg = StudentConfig::realtime();
    cfg.beam.anchor = Some(nldf_core::beam::BeamAnchor {
        centre: [0.02, 0.05, -0.01],
        distance: 2.2,
    });
    let mut spec = crate::util::spec_for(&cfg);
    spec.intrinsics = crate::util::camera_at(128, 128);
    let run = crate::util::write_run_with(&cfg, 61, spec);
    run.scale_weights_like_trained(cfg.n_blocks());
    // Audio that moves pixels past the skipper's threshold, as speech moves a trained
    // head's mouth: skipped frames then re-render coarse cells, not none (with the gain at
    // 1.2 none moves; at 1.5 a page that left out the CNN's reach sent 24096 rays where
    // nldf sent 25008, and its frames strayed 239/255).
    run.scale_audio_weights(1.5);
    let up_dir = run.root.join("upsampler");
    crate::upsampler::write_upsampler(&up_dir, &UpsamplerConfig::with_factor(4), cfg.width, 62);
    let frame_path = run.root.join("frame_up.onnx");
    export_frame_upsampled(&run.student_dir(), &up_dir, &frame_path, WeightType::F32).unwrap();
    let ray_path = run.root.join("model_up.onnx");
    export_student_upsampled(&run.student_dir(), &up_dir, &ray_path, WeightType::F32).unwrap();
    let native_path = run.root.join("frame_native.onnx");
    export_frame(&run.student_dir(), &native_path, WeightType::F32).unwrap();
    let choose = format!("{},{}", frame_path.display(), native_path.display());

    let tmp = tempfile::tempdir().unwrap();
    let wav = tmp.path().join("speech.wav");
    write_test_wav(&wav, 2.0);
    let out = tmp.path().join("browser");
    let model = read_model(&ray_path).unwrap();
    let info = &model.info;
    let windows = windows_from_wav(info, &ray_path, &wav).unwrap();
    let n = windows.n_frames;
    let frames = [0, n / 2, n - 1];
    let default_pose = Mat4::from_cols_array_2d(&info.spec.default_pose).transpose();
    let centre = info.spec.bounds.centre();
    let pose = |(yaw, pitch): (f32, f32)| turn_about(centre, yaw, pitch) * default_pose;
    let n_skip = n.to_string();
    let result = run_page(
        &wav,
        &out,
        &frames,
        &[
            "--model-file",
            frame_path.to_str().unwrap(),
            "--skip-frames",
            &n_skip,
            "--choose",
            &choose,
        ],
    );
    check_choice(&result);
    let status = result["model_status"].as_str().unwrap_or_default();
    assert!(
        status.contains("learned upsampler x4") && status.contains("32 x 32"),
        "the page does not say it holds an upsampler: {status:?}"
    );
    assert_eq!(result["skip_enabled"], true, "skipping is offered for it");
    assert_eq!(
        (result["width"].as_u64(), result["height"].as_u64()),
        (Some(128), Some(128))
    );
    let mut renderer = tract_renderer(&model);
    let parity = check_frames(&result, &out, &mut renderer, &windows, &pose);
    assert_eq!(
        result["frames"].as_array().unwrap().len(),
        frames.len() * POSES.len()
    );
    println!(
        "upsampled frame graph, {} canvas frames against nldf's renderer on the ray graph: \
         {parity}",
        frames.len() * POSES.len()
    );
    check_skipping(&result, &out, &model, &windows, &mut renderer);
}

/// What the page picked among the native and the x4 graph of the same student (offered
/// upsampled first): at a target both reach, the native graph (the most rays); at one
/// neither reaches, the faster as timed, said so; loaded with no model named, the faster of
/// the demo's two frame graphs (fp16 and int8 products), both timed, with a line that says
/// it falls short of 1e9 frames/s.
fn check_choice(result: &serde_json::Value) {
    let picks = result["choice"]
        .as_array()
        .expect("the driver recorded the page's picks");
    assert_eq!(picks.len(), 2);
    for pick in picks {
        let measured = pick["measured"].as_array().unwrap();
        let names: Vec<&str> = measured
            .iter()
            .map(|m| m["name"].as_str().unwrap())
            .collect();
        assert_eq!(
            names,
            ["frame_native.onnx", "frame_up.onnx"],
            "ranked by rays"
        );
        let rays: Vec<u64> = measured
            .iter()
            .map(|m| m["rays"].as_u64().unwrap())
            .collect();
        assert_eq!(rays, [128 * 128, 32 * 32]);
        assert!(
            measured.iter().all(|m| m["fps"].as_f64().unwrap() > 0.0),
            "{pick}"
        );
        assert_eq!(pick["model"].as_str(), pick["picked"].as_str(), "{pick}");
        assert_eq!(pick["width"], 128);
    }
    let (easy, hard) = (&picks[0], &picks[1]);
    assert_eq!(easy["picked"], "frame_native.onnx", "{easy}");
    assert_eq!(easy["reached"], true);
    let note = easy["note"].as_str().unwrap();
    assert!(
        note.starts_with("picked frame_native.onnx") && note.contains("reaching 0.001"),
        "{note:?}"
    );
    let fps = |name: &str| {
        hard["measured"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["name"] == name)
            .unwrap()["fps"]
            .as_f64()
            .unwrap()
    };
    let fastest = if fps("frame_up.onnx") > fps("frame_native.onnx") {
        "frame_up.onnx"
    } else {
        "frame_native.onnx"
    };
    assert_eq!(hard["picked"], fastest, "{hard}");
    assert_eq!(hard["reached"], false);
    let note = hard["note"].as_str().unwrap();
    assert!(
        note.contains("under 1000000000 frames/s: frames will be dropped")
            && note.contains("also timed"),
        "{note:?}"
    );
    let first = &result["default_choice"];
    let model = first["model"].as_str().unwrap_or_default();
    let other = match model {
        "frame.onnx" => "frame_int8.onnx",
        "frame_int8.onnx" => "frame.onnx",
        _ => panic!("the page's default picked {first}"),
    };
    assert_eq!(first["shown"], true);
    let note = first["note"].as_str().unwrap();
    assert!(
        note.starts_with(&format!("picked {model}"))
            && note.contains("under 1000000000")
            && note.contains(&format!("also timed: {other}")),
        "{note:?}"
    );
    println!("the page's picks: {}; {}", easy["note"], hard["note"]);
}

/// nldf's renderer on `model` in tract, 2 threads.
fn tract_renderer(model: &nldf_model::ExportedModel) -> FrameRenderer {
    let options = BackendOptions {
        batch_size: 4096,
        threads: 2,
        spin: true,
    };
    FrameRenderer::new(
        backend_for(model, BackendKind::Tract, options).unwrap(),
        None,
    )
    .unwrap()
}

/// How far the page's canvas frames are from nldf's.
struct CanvasParity {
    /// The largest difference of an 8-bit channel.
    worst: u8,
    /// Channels that differ at all, of `values`.
    changed: usize,
    values: usize,
    /// Of the channels that differ by one step, the largest distance (in 8-bit steps) of
    /// nldf's float value from the rounding boundary between the two bytes: the page's float
    /// value is at least this far from nldf's.
    flip_distance: f32,
}

impl std::fmt::Display for CanvasParity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "worst {}/255, {} of {} channels differ (the page's float value at least {:.4}/255 \
             off nldf's where it rounds to the other byte)",
            self.worst, self.changed, self.values, self.flip_distance
        )
    }
}

/// The page's full frames (`result["frames"]`, every frame at every pose of [`POSES`], files
/// in `out`) against `renderer`'s frames of the same track frames (`windows`) and poses
/// (`pose`): each within [`TOL_8BIT`].
fn check_frames(
    result: &serde_json::Value,
    out: &Path,
    renderer: &mut FrameRenderer,
    windows: &nldf_core::audio::AudioWindows,
    pose: &dyn Fn((f32, f32)) -> Mat4,
) -> CanvasParity {
    let att = renderer.info().audio.att_frames;
    let drawn = result["frames"].as_array().unwrap();
    let mut parity = CanvasParity {
        worst: 0,
        changed: 0,
        values: 0,
        flip_distance: 0.0,
    };
    for entry in drawn {
        let f = entry["frame"].as_u64().unwrap() as usize;
        let p = entry["pose"].as_u64().unwrap() as usize;
        let audio = neighbourhood(windows, f, att);
        let frame = renderer.render(pose(POSES[p]), &audio).unwrap();
        assert!(
            frame.head_pixels > 0,
            "frame {f} pose {p}: the head is in view"
        );
        let want = frame.image.to_rgb8();
        let got = std::fs::read(out.join(entry["file"].as_str().unwrap())).unwrap();
        assert_eq!(got.len(), want.len(), "frame {f} pose {p}: canvas size");
        let (d, changed) = diff_8bit(&got, &want);
        assert!(
            d <= TOL_8BIT,
            "frame {f}, pose {:?}: the canvas is {d}/255 off nldf's frame ({changed} channels differ)",
            POSES[p]
        );
        for ((&g, &w), &v) in got.iter().zip(&want).zip(&frame.image.data) {
            if g.abs_diff(w) == 1 {
                let boundary = f32::from(g.max(w)) - 0.5;
                let x = v.clamp(0.0, 1.0) * 255.0;
                parity.flip_distance = parity.flip_distance.max((x - boundary).abs());
            }
        }
        parity.worst = parity.worst.max(d);
        parity.changed += changed;
        parity.values += got.len();
    }
    parity
}

/// Runs `web/test/browser.mjs` on `wav` into `out` for the track frames `frames` at every
/// pose of [`POSES`], with the driver's `extra` arguments; asserts that it succeeded and the
/// page reported no error, and returns its `result.json`.
fn run_page(wav: &Path, out: &Path, frames: &[usize], extra: &[&str]) -> serde_json::Value {
    let list = frames
        .iter()
        .map(|f| f.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let poses = POSES
        .iter()
        .map(|(y, p)| format!("{y},{p}"))
        .collect::<Vec<_>>()
        .join(";");
    let run = Command::new("node")
        .current_dir(repo())
        .arg("web/test/browser.mjs")
        .args(["--wav", wav.to_str().unwrap()])
        .args(["--out", out.to_str().unwrap()])
        .args(["--frames", &list])
        .args(["--poses", &poses])
        .args(extra)
        .output()
        .unwrap();
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "web/test/browser.mjs failed:\n{log}");
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("result.json")).unwrap()).unwrap();
    for key in ["errors", "page_errors", "console_errors"] {
        let list = result[key].as_array().unwrap();
        assert!(list.is_empty(), "the page reported {key}: {list:?}");
    }
    result
}
