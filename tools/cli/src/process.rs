//! Process measurements: resident memory from /proc and simple timing statistics.

/// Resident set size and its peak in MiB, from `/proc/self/status` (Linux); `None` elsewhere.
pub fn resident_memory_mib() -> Option<(f64, f64)> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let field = |name: &str| -> Option<f64> {
        let line = status.lines().find(|l| l.starts_with(name))?;
        let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib / 1024.0)
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// Median and 90th percentile of durations in milliseconds (sorted copy; empty gives zeros).
pub fn median_and_p90(samples_ms: &[f64]) -> (f64, f64) {
    if samples_ms.is_empty() {
        return (0.0, 0.0);
    }
    let mut sorted = samples_ms.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.9))
}
