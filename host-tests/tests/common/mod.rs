//! What the codegen round-trip and replay-is-the-firmware tests share.

use std::path::Path;

/// Panics unless the committed `file` (from the workspace root) is
/// `fresh`, the generator's text today, naming `command`, which writes it.
#[allow(dead_code)]
pub fn assert_committed_is_fresh(file: &str, command: &str, fresh: &str) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(file);
    let committed =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        committed == fresh,
        "{file} is stale; regenerate with: {command}"
    );
}

/// An alarm event as `replay --json` lists it and as the tests compare
/// it: time \[s\], level, kind and the node.
pub type ListedEvent<N> = (f64, String, String, Option<N>);

/// The `(level, kind)` words `replay` prints for a library event
/// (`coil_thermal_host::observer::describe`), for the events a warning, a
/// predictive alarm and a shutdown raise.
///
/// # Panics
/// On any other event: the tests' traces cannot raise it.
#[allow(dead_code)]
pub fn event_words(kind: coil_thermal::protect::events::EventKind) -> (&'static str, &'static str) {
    let words = coil_thermal_host::observer::describe(kind);
    assert!(
        matches!(words.0, "warning" | "predictive" | "shutdown"),
        "an event this trace cannot raise: {kind:?}"
    );
    words
}

/// The alarm events of a `replay --json` summary.
#[allow(dead_code)]
pub fn json_events(json: &serde_json::Value) -> Vec<ListedEvent<String>> {
    json["alarms"]
        .as_array()
        .expect("an alarms list")
        .iter()
        .map(|e| {
            (
                e["time_s"].as_f64().unwrap_or(f64::NAN),
                e["level"].as_str().unwrap_or_default().to_string(),
                e["kind"].as_str().unwrap_or_default().to_string(),
                e["node"].as_str().map(String::from),
            )
        })
        .collect()
}

/// Whether a value `replay` wrote to its CSV (read as `f64`) is the `f32`
/// `generated` to the bit: `replay` writes each `f32` the observer computed
/// as the shortest decimal that reads back as that `f32`.
#[allow(dead_code)]
pub fn same_f32(replayed: f64, generated: f32) -> bool {
    (replayed as f32).to_bits() == generated.to_bits()
}

/// One trace row as `replay` hands it to the firmware's observer: 1000
/// ticks of 1 ms with the row's `currents_a` \[A\] and `boundary_c`
/// \[degC\] held, `readings_at(now_us)` (the row's sensor readings, sampled
/// at that time \[us\]) given to the first tick only, `now_us` advanced;
/// each event the ticks raise is pushed with its time \[s\].
#[allow(dead_code)]
pub fn tick_row<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
    W: coil_thermal::observer::network::WarmUpKind<X>,
>(
    observer: &coil_thermal::observer::network::NetworkObserver<N, B, M, X, P>,
    state: &mut coil_thermal::observer::network::NetworkObserverState<N, B, M, X, P, W>,
    currents_a: [f32; M],
    boundary_c: [f32; B],
    readings_at: impl Fn(u32) -> [Option<coil_thermal::observer::TimedReading>; P],
    now_us: &mut u32,
    events: &mut Vec<ListedEvent<usize>>,
) {
    for k in 0..1000 {
        *now_us += 1000;
        let inputs = coil_thermal::observer::network::NetworkInputs {
            currents_a,
            boundary_c,
            readings: if k == 0 {
                readings_at(*now_us)
            } else {
                [None; P]
            },
            now_us: *now_us,
            elapsed_us: 1000,
        };
        observer.tick(state, &inputs);
        while let Some(e) = state.events.pop() {
            let (level, kind) = event_words(e.kind);
            events.push((
                f64::from(*now_us) * 1e-6,
                level.to_string(),
                kind.to_string(),
                e.element,
            ));
        }
    }
}
