//! Where the time of `flexmb check` goes: reading the model file (TOML parse, building the
//! model, `Model::validate`) against setting up the solver (`Simulation::new`: layout,
//! sparsity pattern and symbolic LU, consistent initial accelerations).
//!
//! ```sh
//! cargo run --release -p flexmb --example check_timing -- MODEL.toml
//! ```

use flexmb::input::{read_model_file, Analysis};
use flexmb::solve::{initial_accelerations, prepare_layout};
use flexmb::{Data, State};

/// CPU seconds of this process (user + system) from /proc/self/stat, 10 ms resolution: the
/// machine may be shared, so wall time would mislead.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("Linux /proc");
    // Fields after the command name (which is in parentheses): utime and stime are 14 and 15.
    let rest = &stat[stat.rfind(')').expect("stat format") + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    ticks / 100.0
}

struct Instant(f64);

impl Instant {
    fn now() -> Self {
        Self(cpu_seconds())
    }
    fn elapsed(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(cpu_seconds() - self.0)
    }
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: check_timing MODEL.toml");
    let t = Instant::now();
    let file = read_model_file(path.as_ref(), &[]).unwrap_or_else(|e| panic!("{e}"));
    let read = t.elapsed().as_secs_f64();
    let t = Instant::now();
    file.model.validate().unwrap_or_else(|e| panic!("{e}"));
    let validate = t.elapsed().as_secs_f64();
    let Analysis::Dynamic(settings) = file.analysis else {
        panic!("a dynamic model")
    };
    let t = Instant::now();
    let (layout, _) = prepare_layout(&file.model);
    let layout_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut state = State::initial(&file.model, &layout);
    let mut data = Data::new(&file.model, layout).unwrap_or_else(|e| panic!("{e}"));
    let data_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    initial_accelerations(
        &file.model,
        &mut data,
        &mut state,
        settings.load_factor_at(0.0),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let initial = t.elapsed().as_secs_f64();
    println!(
        "{path} (CPU seconds): read (parse + build + validate) {read:.3} s (of which validate {validate:.3} s); solver set-up: layout {layout_s:.3} s, data (pattern, symbolic LU) {data_s:.3} s, initial accelerations {initial:.3} s"
    );
}
