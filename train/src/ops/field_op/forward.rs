//! The fused field's forward pass: layer by layer over blocks of whole rays.

use candle_core::Result;
use rayon::prelude::*;

use super::{FieldOp, PackedPlan, Stash, trunk_width};
use crate::kernels::{Addend, Epilogue, Packed, block_product, take_buffer};
use crate::ops::op_base::{Affine, bias_of};

/// One block's activations: each trunk layer's output, the feature and the colour layer.
struct BlockActs<'a> {
    trunk: Vec<&'a mut [f32]>,
    feature: &'a mut [f32],
    color: &'a mut [f32],
}

/// One block's inputs: `rows` rows of the points and the per-ray terms of their rays.
#[derive(Clone, Copy)]
struct BlockInput<'a> {
    points: &'a [f32],
    rays: &'a [f32],
    rows: usize,
}

impl FieldOp {
    /// The forward pass over one block of whole rays: the block's points and per-ray
    /// terms in `input`, outputs into `acts` and `out` (`[rows, 4]`: raw density, raw
    /// rgb).
    fn forward_block(
        &self,
        w: &PackedPlan,
        params: &[f32],
        input: BlockInput<'_>,
        acts: &mut BlockActs<'_>,
        out: &mut [f32],
    ) -> Result<()> {
        let plan = &self.plan;
        let group = Addend::Group(plan.n_samples);
        let rw = plan.ray_width;
        let BlockInput { rays, rows, .. } = input;
        let in_width = self.forward_trunk(w, params, input, &mut acts.trunk)?;
        let h = acts
            .trunk
            .last()
            .map(|h| &**h)
            .ok_or_else(|| candle_core::Error::Msg("fused field: empty trunk".into()))?;
        let (d, f, c, r) = (&plan.density, &plan.feature, &plan.color, &plan.rgb);
        let bias = |a: &Affine| Epilogue {
            bias: bias_of(params, a),
            ..Epilogue::default()
        };
        block_product(h, in_width, rows, &w.density, out, 4, bias(d));
        block_product(h, in_width, rows, &w.feature, acts.feature, f.out, bias(f));
        block_product(
            acts.feature,
            f.out,
            rows,
            &w.color,
            acts.color,
            c.out,
            Epilogue {
                addend: Some((&rays[plan.color_ray..], rw, group)),
                relu: true,
                ..Epilogue::default()
            },
        );
        block_product(acts.color, c.out, rows, &w.rgb, &mut out[1..], 4, bias(r));
        Ok(())
    }

    /// The trunk's forward over one block: each layer's output into its slice of `trunk`.
    /// Returns the last layer's width.
    fn forward_trunk(
        &self,
        w: &PackedPlan,
        params: &[f32],
        input: BlockInput<'_>,
        trunk: &mut [&mut [f32]],
    ) -> Result<usize> {
        let plan = &self.plan;
        let rows = input.rows;
        let mut in_width = 0;
        for (i, (step, (wh, wp))) in plan.trunk.iter().zip(&w.trunk).enumerate() {
            let width = trunk_width(step)?;
            let (done, rest) = trunk.split_at_mut(i);
            let y = &mut *rest[0];
            let prev = done.last().map(|x| &**x);
            match (step.hidden, wh, wp, step.ray, prev) {
                // relu(points W_p^T + ray term), the ray term carrying the bias.
                (None, None, Some(wp), Some(off), _) => {
                    self.points_term(input, wp, off, y, width, true)
                }
                // relu(x W_h^T + points W_p^T + ray term).
                (Some(_), Some(wh), Some(wp), Some(off), Some(x)) => {
                    self.points_term(input, wp, off, y, width, false);
                    block_product(
                        x,
                        in_width,
                        rows,
                        wh,
                        y,
                        width,
                        Epilogue {
                            accumulate: true,
                            relu: true,
                            ..Epilogue::default()
                        },
                    );
                }
                // relu(x W_h^T + b_h).
                (Some(h), Some(wh), None, _, Some(x)) => block_product(
                    x,
                    in_width,
                    rows,
                    wh,
                    y,
                    width,
                    Epilogue {
                        bias: bias_of(params, &h),
                        relu: true,
                        ..Epilogue::default()
                    },
                ),
                _ => candle_core::bail!("fused field: a trunk layer lacks its input"),
            }
            in_width = width;
        }
        Ok(in_width)
    }

    /// `y = act(points W_p^T + the ray term at column off)` over one block, `act` a ReLU
    /// when `relu`.
    fn points_term(
        &self,
        input: BlockInput<'_>,
        wp: &Packed,
        off: usize,
        y: &mut [f32],
        width: usize,
        relu: bool,
    ) {
        let group = Addend::Group(self.plan.n_samples);
        let addend = Some((&input.rays[off..], self.plan.ray_width, group));
        block_product(
            input.points,
            wp.k(),
            input.rows,
            wp,
            y,
            width,
            Epilogue {
                addend,
                relu,
                ..Epilogue::default()
            },
        )
    }

    /// The forward pass on raw slices, in parallel over blocks of rays; returns `[n, 4]`
    /// (raw density, raw rgb) and, when kept, the activations.
    pub(super) fn run(
        &self,
        points: &[f32],
        params: &[f32],
        rays: &[f32],
        n: usize,
    ) -> Result<(Vec<f32>, Stash)> {
        let plan = &self.plan;
        let pos_dim = self.pos_dim()?;
        let widths = plan
            .trunk
            .iter()
            .map(trunk_width)
            .collect::<Result<Vec<_>>>()?;
        let (f_out, c_out, rw) = (plan.feature.out, plan.color.out, plan.ray_width);
        let w = PackedPlan::new(plan, params, true);
        let rays_per_block = self.rays_per_block();
        let rb = rays_per_block * plan.n_samples;
        let mut out = vec![0.0f32; n * 4];
        let jobs = out
            .chunks_mut(rb * 4)
            .zip(points.chunks(rb * pos_dim))
            .zip(rays.chunks(rays_per_block * rw))
            .map(|((o, points), rays)| {
                let rows = o.len() / 4;
                (o, BlockInput { points, rays, rows })
            });
        if self.keep {
            let mut stash = Stash {
                trunk: widths.iter().map(|&wd| take_buffer(n * wd)).collect(),
                feature: take_buffer(n * f_out),
                color: take_buffer(n * c_out),
            };
            stash_blocks(&mut stash, &widths, rb, f_out, c_out)
                .into_par_iter()
                .zip(jobs.collect::<Vec<_>>())
                .try_for_each(|(mut acts, (o, input))| {
                    self.forward_block(&w, params, input, &mut acts, o)
                })?;
            Ok((out, stash))
        } else {
            jobs.collect::<Vec<_>>().into_par_iter().try_for_each_init(
                || {
                    (
                        widths
                            .iter()
                            .map(|&wd| vec![0.0f32; rb * wd])
                            .collect::<Vec<_>>(),
                        vec![0.0f32; rb * f_out],
                        vec![0.0f32; rb * c_out],
                    )
                },
                |(trunk, feature, color), (o, input)| {
                    let mut acts = BlockActs {
                        trunk: trunk.iter_mut().map(|t| &mut t[..]).collect(),
                        feature,
                        color,
                    };
                    self.forward_block(&w, params, input, &mut acts, o)
                },
            )?;
            Ok((out, Stash::default()))
        }
    }
}

/// The kept activations cut into blocks of `rb` rows: each block's rows of every trunk
/// layer's output (of `widths`), of the feature and of the colour layer.
fn stash_blocks<'a>(
    stash: &'a mut Stash,
    widths: &[usize],
    rb: usize,
    f_out: usize,
    c_out: usize,
) -> Vec<BlockActs<'a>> {
    let mut blocks: Vec<BlockActs<'_>> = stash
        .feature
        .chunks_mut(rb * f_out)
        .zip(stash.color.chunks_mut(rb * c_out))
        .map(|(feature, color)| BlockActs {
            trunk: Vec::with_capacity(widths.len()),
            feature,
            color,
        })
        .collect();
    for (buf, &wd) in stash.trunk.iter_mut().zip(widths) {
        for (b, chunk) in blocks.iter_mut().zip(buf.chunks_mut(rb * wd)) {
            b.trunk.push(chunk);
        }
    }
    blocks
}
