//! `cargo bench -p data`: windows/s for T = 16 at 64² and 128², 1 and 2 workers.

fn main() {
    let dir = tempfile::tempdir().expect("temporary directory");
    data::bench::make_bench_dataset(dir.path(), 4, 80, 128).expect("bench dataset");
    let results =
        data::bench::bench_windows(dir.path(), 16, &[64, 128], &[1, 2], 128).expect("bench");
    println!(
        "{:>6} {:>6} {:>8} {:>9} {:>12}",
        "T", "size", "workers", "windows", "windows/s"
    );
    for r in results {
        println!(
            "{:>6} {:>6} {:>8} {:>9} {:>12.1}",
            r.window, r.image_size, r.workers, r.windows, r.windows_per_s
        );
    }
}
