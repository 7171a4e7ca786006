use mtpcr_core::*;
use std::time::Instant;
fn main() {
    let p = io::Problem::load("../shared/problems/bunny-a.json", None).unwrap();
    let t = Instant::now();
    let clouds = p.read_scans().unwrap();
    eprintln!("read {:.3}", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let idx = clouds[0].farthest_point_indices(2013);
    eprintln!("fps one cloud {:.3} ({})", t.elapsed().as_secs_f64(), idx.len());
    let cfg = Config { seed: Some(1), ..Config::default() };
    let t = Instant::now();
    let prep = PreparedProblem::new(&clouds, &cfg).unwrap();
    eprintln!("prepare {:.3} eps {} shift {}", t.elapsed().as_secs_f64(), prep.eps(), prep.shift());
    for c in prep.clouds() { eprintln!("  pts {} fast mem {} KB", c.points().len(), c.fast_memory_bytes()/1024); }
    let t = Instant::now();
    let r = prep.register(&cfg, None).unwrap();
    eprintln!("evolve {:.3} evals {}", t.elapsed().as_secs_f64(), r.evaluations);
}
