//! What nldf finds on this machine, for `nldf doctor`: the CPU's vector features and
//! threads, the onnxruntime library (and where in the search order it was found), ffmpeg
//! and Python.

use std::path::Path;
use std::process::Command;

use crate::ort_library::{OrtSearch, on_path};
use crate::video::ffmpeg_on_path;

/// One line of the report: what was checked, and what was found.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// What was checked.
    pub what: &'static str,
    /// What was found, or what is missing and how to get it.
    pub found: String,
}

/// Everything `nldf doctor` reports.
pub fn findings() -> Vec<Finding> {
    let mut out = vec![
        Finding {
            what: "CPU",
            found: nldf_core::host::cpu_model().unwrap_or_else(|| "unknown".into()),
        },
        Finding {
            what: "vector features",
            found: cpu_features(),
        },
        Finding {
            what: "int8 path",
            found: int8_path(),
        },
        Finding {
            what: "threads",
            found: std::thread::available_parallelism()
                .map_or_else(|_| "unknown".into(), |n| n.get().to_string()),
        },
    ];
    out.push(Finding {
        what: "onnxruntime",
        found: match OrtSearch::from_env().find() {
            Ok(f) => format!(
                "{} ({}; from {})",
                f.version().unwrap_or_else(|| "version unknown".into()),
                f.path.display(),
                f.place
            ),
            Err(e) => {
                let message = e.to_string();
                let message = message.strip_prefix("onnxruntime: ").unwrap_or(&message);
                format!("not found: {message}")
            }
        },
    });
    out.push(Finding {
        what: "ffmpeg",
        found: match ffmpeg_on_path() {
            Some(p) => first_line(&p, "-version").unwrap_or_else(|| p.display().to_string()),
            None => "not on the PATH (videos are written as PNG frames only; --ffmpeg PATH \
                     names one)"
                .into(),
        },
    });
    out.push(Finding {
        what: "python3",
        found: match on_path("python3") {
            Some(p) => first_line(&p, "--version").unwrap_or_else(|| p.display().to_string()),
            None => "not on the PATH".into(),
        },
    });
    out
}

/// The first line a program prints for `flag`.
fn first_line(program: &Path, flag: &str) -> Option<String> {
    let out = Command::new(program).arg(flag).output().ok()?;
    let text = if out.stdout.is_empty() {
        out.stderr
    } else {
        out.stdout
    };
    String::from_utf8_lossy(&text)
        .lines()
        .next()
        .map(|l| l.trim().to_string())
}

/// Which kernel family onnxruntime's u8 x s8 products take on this CPU.
fn int8_path() -> String {
    let bound = format!(
        "nldf's int8 weights are 7-bit: a pair of products reaches at most {}, within the \
         32767 of a 16-bit sum",
        nldf_model::contract::int8_pair_sum_max()
    );
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512vnni")
            || std::arch::is_x86_feature_detected!("avxvnni")
        {
            return format!("VNNI: products summed in 32 bits, no saturation ({bound})");
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            return format!(
                "AVX2 without VNNI: pairs of products summed in saturating 16 bits ({bound})"
            );
        }
        format!("no AVX2: portable int8 kernels ({bound})")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        format!("not x86-64: the runtime's own int8 kernels ({bound})")
    }
}

/// The vector features the kernels and runtimes use, present or absent.
fn cpu_features() -> String {
    #[cfg(target_arch = "x86_64")]
    {
        let features = [
            ("AVX2", std::arch::is_x86_feature_detected!("avx2")),
            ("FMA", std::arch::is_x86_feature_detected!("fma")),
            ("AVX-512F", std::arch::is_x86_feature_detected!("avx512f")),
            (
                "AVX-512 VNNI",
                std::arch::is_x86_feature_detected!("avx512vnni"),
            ),
            (
                "AVX-512 FP16",
                std::arch::is_x86_feature_detected!("avx512fp16"),
            ),
        ];
        features
            .iter()
            .map(|(name, on)| format!("{name} {}", if *on { "yes" } else { "no" }))
            .collect::<Vec<_>>()
            .join(", ")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        "not an x86-64 CPU: nldf's AVX-512 kernels fall back to portable code".to_string()
    }
}
