use super::*;
use nldf_core::composite::composite_weights;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn unit_box() -> Bounds {
    Bounds {
        lo: Vec3::splat(-1.0),
        hi: Vec3::splat(1.0),
    }
}

/// A mask of `r^3` cells, occupied where `f(x, y, z)` says, without dilation.
fn mask_where(r: usize, f: impl Fn(usize, usize, usize) -> bool) -> OccupancyMask {
    let mut occupied = Vec::with_capacity(r * r * r);
    for z in 0..r {
        for y in 0..r {
            for x in 0..r {
                occupied.push(f(x, y, z));
            }
        }
    }
    OccupancyMask {
        resolution: r,
        bounds: unit_box(),
        occupied,
    }
}

/// Rays along +z (scaled directions) through the box at a few (x, y), from z = -3.
fn rays_along_z() -> Rays {
    let mut rays = Rays::with_capacity(6);
    for (x, y) in [
        (0.1, 0.2),
        (-0.7, 0.33),
        (0.9, -0.9),
        (0.0, 0.0),
        (0.45, -0.05),
    ] {
        rays.push(Vec3::new(x, y, -3.0), Vec3::new(0.0, 0.0, 2.0));
    }
    // One ray that misses the box.
    rays.push(Vec3::new(5.0, 5.0, -3.0), Vec3::new(0.0, 0.0, 1.0));
    rays
}

#[test]
fn a_ray_through_occupied_cells_only_gets_the_stratified_samples() {
    let rays = rays_along_z();
    // Every cell occupied but one corner no ray crosses.
    let mask = mask_where(8, |x, y, z| (x, y, z) != (0, 7, 0));
    assert!(!mask.all());
    for jitter in [false, true] {
        let mut g1 = ChaCha8Rng::seed_from_u64(3);
        let mut g2 = ChaCha8Rng::seed_from_u64(3);
        let (r1, r2) = if jitter {
            (Some(&mut g1), Some(&mut g2))
        } else {
            (None, None)
        };
        let occ = sample_occupied(&rays, &unit_box(), 0.0, 10.0, 16, &mask, r1);
        let plain = sample_stratified(&rays, &unit_box(), 0.0, 10.0, 16, r2);
        assert_eq!(occ.hit, plain.hit);
        assert_eq!(occ.spans, plain.spans);
        for (a, b) in occ.t_vals.iter().zip(&plain.t_vals) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        for (a, b) in occ.deltas.iter().zip(&plain.deltas) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }
}

#[test]
fn samples_skip_empty_cells_and_their_spacings_add_up_to_the_occupied_length() {
    let rays = rays_along_z();
    // Only the slab 2 <= z < 5 of 8 cells (z in [-0.5, 0.25)) and the top cell are
    // occupied: 1 world unit along z (spacings are in world units).
    let mask = mask_where(8, |_, _, z| (2..5).contains(&z) || z == 7);
    let occupied_len = 4.0 * 0.25;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let s = sample_occupied(&rays, &unit_box(), 0.0, 10.0, 12, &mask, Some(&mut rng));
    assert_eq!(s.hit, vec![0, 1, 2, 3, 4]);
    for h in 0..s.hit.len() {
        let deltas = &s.deltas[12 * h..12 * (h + 1)];
        // As in `sample_stratified`, the spacings run from the first sample on: the occupied
        // length before it (from the slab's entry at z = -0.5) is the rest.
        let lead = s.points[3 * 12 * h + 2] + 0.5;
        let sum: f32 = deltas.iter().sum();
        assert!(
            (sum + lead - occupied_len).abs() < 1e-4,
            "ray {h}: {sum} + {lead}"
        );
        let t = &s.t_vals[12 * h..12 * (h + 1)];
        assert!(t.windows(2).all(|w| w[0] < w[1]), "ray {h}: {t:?}");
        for k in 0..12 {
            let z = s.points[3 * (12 * h + k) + 2];
            assert!((-0.5..0.25).contains(&z) || z >= 0.75, "ray {h}: z {z}");
        }
    }
}

#[test]
fn a_ray_through_empty_cells_only_composites_to_its_background() {
    let rays = rays_along_z();
    let mask = mask_where(4, |_, _, _| false);
    let s = sample_occupied::<ChaCha8Rng>(&rays, &unit_box(), 0.0, 10.0, 8, &mask, None);
    assert_eq!(s.hit.len(), 5);
    assert!(s.deltas.iter().all(|&d| d == 0.0));
    assert!(s.t_vals.iter().all(|t| t.is_finite()));
    let mut w = vec![0.0f32; 8];
    composite_weights(&[1e10; 8], &s.deltas[..8], &mut w);
    assert!(w.iter().all(|&w| w == 0.0), "{w:?}");
}

#[test]
fn a_constant_density_in_a_slab_is_as_opaque_as_its_thickness_says() {
    // σ = 3 inside the occupied slab, whose thickness along the ray is 0.75 world units
    // (direction of length 2: t covers 0.375). The samples sit at the centres of 32 equal
    // strata and the spacings run from the first on: optical depth 3 (0.75 - 0.75 / 64).
    let rays = rays_along_z();
    let mask = mask_where(8, |_, _, z| (2..5).contains(&z));
    let s = sample_occupied::<ChaCha8Rng>(&rays, &unit_box(), 0.0, 10.0, 32, &mask, None);
    let mut w = vec![0.0f32; 32];
    composite_weights(&[3.0; 32], &s.deltas[..32], &mut w);
    let opacity: f64 = w.iter().map(|&w| w as f64).sum();
    let expected = 1.0 - (-3.0f64 * (0.75 - 0.75 / 64.0)).exp();
    assert!((opacity - expected).abs() < 1e-5, "{opacity} vs {expected}");
}

#[test]
fn a_cell_above_the_threshold_occupies_itself_and_its_neighbours() {
    let r = 6;
    let cell = 2.0 / r as f32;
    let threshold = -(1.0f32 - 0.01).ln() / cell;
    let at = |x: usize, y: usize, z: usize| (z * r + y) * r + x;
    let mut density = vec![0.0f32; r * r * r];
    // A dense top slab lifts the mean far above the threshold, so the threshold decides.
    density[at(0, 0, 5)..].fill(100.0 * threshold);
    density[at(2, 3, 1)] = threshold * 1.01;
    density[at(5, 0, 0)] = threshold * 0.99;
    let mask = OccupancyMask::from_density(&density, r, unit_box(), 0.01);
    let count = mask.occupied.iter().filter(|&&o| o).count();
    assert_eq!(count, 27 + 2 * r * r);
    assert!(mask.occupied[at(1, 2, 0)] && mask.occupied[at(3, 4, 2)]);
    assert!(!mask.occupied[at(5, 0, 0)] && !mask.occupied[at(0, 0, 3)]);
    // Unmeasured cells count as occupied.
    let fresh = OccupancyMask::from_density(&vec![UNMEASURED; r * r * r], r, unit_box(), 0.01);
    assert!(fresh.all());
}

#[test]
fn a_faint_field_keeps_the_cells_at_or_above_its_mean() {
    // A young field far below the threshold everywhere: the cell above the mean stays.
    let r = 5;
    let mut density = vec![1e-3f32; r * r * r];
    density[(r + 1) * r + 1] = 2e-3;
    let mask = OccupancyMask::from_density(&density, r, unit_box(), 0.01);
    assert_eq!(mask.occupied.iter().filter(|&&o| o).count(), 27);
    assert!(mask.occupied[0]);
}

#[test]
fn a_cell_keeps_the_larger_of_its_decayed_density_and_the_new_draw() {
    let old = [UNMEASURED, 10.0, 10.0, 10.0, 10.0];
    let new = [4.0, 2.0, 20.0, f32::NAN, -5.0];
    let got = absorbed(&old, &new, 0.5);
    assert_eq!(got, vec![4.0, 5.0, 20.0, f32::MAX, 5.0]);
    assert!(got.iter().all(|v| v.is_finite()));
}

#[test]
fn every_cell_point_lies_in_its_cell() {
    let cfg = OccupancyConfig {
        resolution: 5,
        ..OccupancyConfig::default()
    };
    let bounds = Bounds {
        lo: Vec3::new(-1.0, 0.0, 2.0),
        hi: Vec3::new(1.0, 0.5, 3.0),
    };
    let density = Var::zeros(125, candle_core::DType::F32, &Device::Cpu).unwrap();
    let occ = Occupancy::new(&cfg, bounds, density);
    let points = occ.cell_points(&mut ChaCha8Rng::seed_from_u64(1));
    assert_eq!(points.len(), 3 * 125);
    for (i, p) in points.chunks_exact(3).enumerate() {
        let (x, y, z) = (i % 5, (i / 5) % 5, i / 25);
        let u = (Vec3::from_slice(p) - bounds.lo) / (bounds.hi - bounds.lo) * 5.0;
        assert_eq!(
            (u.x as usize, u.y as usize, u.z as usize),
            (x, y, z),
            "{p:?}"
        );
    }
    occ.reset().unwrap();
    assert!(occ.mask().unwrap().all());
    // One dense cell in the middle: it and its neighbours stay.
    let mut sigma = vec![0.0; 125];
    sigma[62] = 1e6;
    occ.absorb(&sigma).unwrap();
    assert_eq!(occ.mask().unwrap().fraction(), 27.0 / 125.0);
}

#[test]
fn updates_start_after_the_warmup_and_come_every_few_steps() {
    let occ = Occupancy::new(
        &OccupancyConfig {
            warmup_steps: 10,
            update_every: 4,
            ..OccupancyConfig::default()
        },
        unit_box(),
        Var::zeros(1, candle_core::DType::F32, &Device::Cpu).unwrap(),
    );
    let due: Vec<usize> = (0..24).filter(|&s| occ.due(s)).collect();
    assert_eq!(due, vec![10, 14, 18, 22]);
}
