use sim::task::registry;
fn main() {
    let task = registry::resolve(&std::env::args().nth(1).unwrap()).unwrap();
    let seed: u64 = std::env::args().nth(2).unwrap().parse().unwrap();
    let mut cfg = sim::EnvConfig {
        render: false,
        ..Default::default()
    };
    cfg.settle_steps = std::env::args()
        .nth(3)
        .map(|s| s.parse().unwrap())
        .unwrap_or(20);
    let mut env = sim::Env::from_task(&task, cfg).unwrap();
    let t0 = std::time::Instant::now();
    let r = env.reset(seed);
    println!("reset {:?}: {:?}", t0.elapsed(), r.as_ref().err());
    let scene = env.scene().unwrap();
    for i in &scene.instances {
        println!(
            "{} {:?}",
            i.name,
            env.data()
                .body_pos(i.root_body)
                .map(|v| (v * 1000.0).round() / 1000.0)
        );
    }
    let t0 = std::time::Instant::now();
    for _ in 0..20 {
        env.step(&[0.0; 7]).unwrap();
    }
    println!("20 steps {:?}", t0.elapsed());
}
