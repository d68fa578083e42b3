use std::time::Instant;
fn main() {
    let (m, k, n) = (31296usize, 128usize, 128usize);
    let x: Vec<f32> = (0..m * k).map(|i| (i % 7) as f32 * 0.1).collect();
    let w: Vec<f32> = (0..n * k).map(|i| (i % 5) as f32 * 0.1).collect();
    let mut y = vec![0.0f32; m * n];
    for (name, f) in [("forward", 0), ("matmul", 1), ("matmul_tn", 2)] {
        let t = Instant::now();
        let mut reps = 0;
        while t.elapsed().as_secs_f64() < 1.0 {
            match f {
                0 => nldf_train::kernels::linear_forward(
                    &x,
                    m,
                    k,
                    &w,
                    n,
                    &[],
                    nldf_train::kernels::Addend::None,
                    true,
                    &mut y,
                ),
                1 => nldf_train::kernels::matmul(&x, m, k, &w, n, &mut y),
                _ => {
                    let mut c = vec![0.0; n * k];
                    nldf_train::kernels::matmul_tn(&y, m, n, &x, k, &mut c)
                }
            }
            reps += 1;
        }
        let gf = 2.0 * (m * k * n) as f64 * reps as f64 / t.elapsed().as_secs_f64() / 1e9;
        println!("{name}: {gf:.1} GFLOP/s");
    }
}
