//! What the benchmarks share.

/// Peak resident memory of this process [MB] (Linux).
pub fn peak_memory_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .map(|v| v.parse::<f64>().unwrap_or(0.0) / 1024.0)
            })
        })
        .unwrap_or(f64::NAN)
}
