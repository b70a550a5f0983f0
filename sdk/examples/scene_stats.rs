//! Occlusion statistics of the default random scenes (the figures quoted in `docs/DATASET.md`).
//!
//! `cargo run --release -p tensorholo --example scene_stats -- [SCENES] [SIZE]` (default 100 scenes of
//! 384×384, seeds 0..SCENES): mean valid fraction per LDI layer, fraction of pixels with at least two
//! layers, histogram of the first layer's depth, the time per scene, and the mean number of non-empty
//! SM-LBM planes (= propagations per colour) at 2048 and 10,000 levels.

use tensorholo::dataset::LdiStatistics;
use tensorholo::scene::{RandomSceneConfig, RandomSceneGenerator};
use tensorholo::synthesis::{ldi_layers, SmLbm};

fn main() -> tensorholo::Result<()> {
    let mut args = std::env::args().skip(1);
    let scenes: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(100);
    let size: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(384);
    let config = RandomSceneConfig {
        height: size,
        width: size,
        ..RandomSceneConfig::default()
    };
    let generator = RandomSceneGenerator::new(config.clone())?;
    let mut valid = vec![0.0; config.layers];
    let (mut multi, mut multi_min, mut layers) = (0.0, f64::INFINITY, 0.0);
    let mut histogram = [0usize; 10];
    let levels = [2048usize, 10_000];
    let mut planes = [0.0f64; 2];
    let mut seconds = 0.0;
    for seed in 0..scenes {
        let t = std::time::Instant::now();
        let ldi = generator.generate(seed)?;
        seconds += t.elapsed().as_secs_f64();
        for (p, &n) in planes.iter_mut().zip(&levels) {
            let sm = SmLbm {
                levels: n,
                ..SmLbm::default()
            };
            *p += sm.propagation_count(&ldi_layers(&ldi))? as f64 / scenes as f64;
        }
        let st = LdiStatistics::of(&ldi);
        for (a, v) in valid.iter_mut().zip(&st.valid_fraction) {
            *a += v / scenes as f64;
        }
        multi += st.multi_layer_fraction / scenes as f64;
        multi_min = multi_min.min(st.multi_layer_fraction);
        layers += st.mean_valid_layers / scenes as f64;
        for &d in &ldi.layers()[0].depth {
            histogram[((d * 10.0) as usize).min(9)] += 1;
        }
    }
    let total: usize = histogram.iter().sum();
    println!(
        "{scenes} scenes of {size}x{size}, {:.3} s per scene",
        seconds / scenes as f64
    );
    println!("mean valid fraction per layer: {valid:.3?}");
    println!("pixels with >= 2 layers: mean {multi:.3}, min {multi_min:.3}; mean valid layers {layers:.2}");
    println!(
        "first-layer depth histogram (%, bins of 0.1 from near): {:?}",
        histogram.map(|h| (1000.0 * h as f64 / total as f64).round() / 10.0)
    );
    println!(
        "non-empty SM-LBM planes: {:.0} of 2048, {:.0} of 10000",
        planes[0], planes[1]
    );
    Ok(())
}
