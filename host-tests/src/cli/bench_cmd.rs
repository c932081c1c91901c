//! `coil-thermal bench`.

use std::time::Duration;

use anyhow::{bail, Result};
use serde_json::json;

use super::common;
use super::BenchArgs;
use crate::observer::STEP_BUDGET_NS;

/// Runs `bench`.
pub fn run(a: BenchArgs) -> Result<()> {
    if a.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    let timings = crate::bench::run(Duration::from_millis(a.min_time_ms), a.repeats);
    if a.json {
        let mut map = serde_json::Map::new();
        for t in &timings {
            map.insert(t.key.clone(), json!(t.ns));
            let stem = t.key.strip_suffix("_ns").unwrap_or(&t.key);
            map.insert(format!("{stem}_budget_ratio"), json!(t.budget_ratio));
        }
        map.insert("budget_ns".into(), json!(STEP_BUDGET_NS));
        map.insert("command".into(), json!("bench"));
        common::print_json(&serde_json::Value::Object(map));
        return Ok(());
    }
    println!(
        "per-step time on this host (median of {} runs; {} build)",
        a.repeats,
        if cfg!(debug_assertions) {
            "DEBUG"
        } else {
            "release"
        }
    );
    println!(
        "{:<34} {:>12} {:>16}",
        "step", "time [ns]", "of 0.1 ms budget"
    );
    for t in &timings {
        println!("{:<34} {:>12.1} {:>15.5}", t.key, t.ns, t.budget_ratio);
    }
    Ok(())
}
