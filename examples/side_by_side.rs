//! Frames side by side, cropped and enlarged: one row per frame id, one column per folder
//! of `<id>.png` renders (the truth, then each model), so that small detail (eyes, nose,
//! teeth) can be compared.
//!
//! Usage: cargo run --release --example side_by_side -- OUT.png SCALE X,Y,W,H ID,ID,.. DIR..
//! (the crop's corner and size in pixels, enlarged SCALE times by repeating pixels).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use nldf_core::image::{ImageRgb, grid};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [out, scale, crop, ids, dirs @ ..] = args.as_slice() else {
        bail!("usage: side_by_side OUT.png SCALE X,Y,W,H ID,ID,.. DIR..");
    };
    if dirs.is_empty() {
        bail!("give at least one folder of renders");
    }
    let scale: u32 = scale.parse().context("SCALE must be a whole number")?;
    let crop: Vec<u32> = crop
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()
        .context("the crop is X,Y,W,H in whole pixels")?;
    let [x, y, w, h] = crop[..] else {
        bail!("the crop is X,Y,W,H");
    };
    let mut rows = Vec::new();
    for id in ids.split(',') {
        let mut row = Vec::new();
        for dir in dirs {
            let path = Path::new(dir).join(format!("{id}.png"));
            let image = ImageRgb::load(&path)?;
            if x + w > image.width || y + h > image.height {
                bail!(
                    "{}: the crop {x},{y},{w},{h} leaves the {}x{} image",
                    path.display(),
                    image.width,
                    image.height
                );
            }
            let mut part = ImageRgb::filled(w, h, [0.0; 3]);
            for j in 0..h {
                for i in 0..w {
                    part.set(i, j, image.get(x + i, y + j));
                }
            }
            row.push(part.upscaled(scale));
        }
        rows.push(row);
    }
    let out = PathBuf::from(out);
    grid(&rows, 2, [1.0; 3]).save_png(&out)?;
    println!("wrote {}", out.display());
    Ok(())
}
