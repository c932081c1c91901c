//! Writes the synthetic current traces to `host-tests/traces/*.csv`.
//!
//! `cargo run -p coil-thermal-host --bin gen-traces`; the replay tests check
//! that the committed files equal this output.
use coil_thermal_host::traces;

fn main() -> std::io::Result<()> {
    let dir = traces::trace_dir();
    std::fs::create_dir_all(&dir)?;
    for (name, description, trace) in traces::all() {
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, trace.to_csv(name, &description))?;
        println!("{} ({} rows)", path.display(), trace.times_s.len());
    }
    Ok(())
}
