//! Redraws a training curve from a `log.csv`: `plot_log LOG.csv OUT.png [TITLE]`.
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: plot_log LOG.csv OUT.png [TITLE]".into());
    }
    let rows = nldf_train::trainers::log::read_log(std::path::Path::new(&args[1]))?;
    let title = args.get(3).map(String::as_str).unwrap_or("training curve");
    nldf_train::trainers::plot::plot_training_curve(std::path::Path::new(&args[2]), title, &rows)?;
    Ok(())
}
