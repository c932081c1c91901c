//! One second of a recording at 1 ms ticks, shared by the replays whose
//! host and firmware runs must print the same lines (`roundtrip.rs`,
//! `three_phase.rs`): the row's currents and boundaries held for the
//! second, each sensor's reading (if any) given to the second's first tick
//! with that tick's time, every tick's outputs folded into the checksum.

use coil_thermal::observer::network::{
    NetworkInputs, NetworkObserver, NetworkObserverState, WarmUpKind,
};
use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;

#[path = "checksum.rs"]
mod checksum;
pub use checksum::START;

/// Ticks per second.
pub const TICKS: u32 = 1000;

/// Runs one second: [`TICKS`] ticks of 1 ms from `now_us` \[us\] (advanced,
/// wrapping), each run by `tick` (the firmware counts its instructions
/// there; the tick returns the model steps it took); returns the ticks that
/// made a correction.
///
/// # Errors
/// A tick that did not run.
#[allow(clippy::too_many_arguments)]
pub fn run<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
    W: WarmUpKind<X>,
>(
    observer: &NetworkObserver<N, B, M, X, P>,
    state: &mut NetworkObserverState<N, B, M, X, P, W>,
    currents_a: [f32; M],
    boundary_c: [f32; B],
    readings_c: [Option<f32>; P],
    now_us: &mut u32,
    checksum: &mut u32,
    tick: &mut impl FnMut(&mut dyn FnMut() -> u32),
) -> Result<u32, &'static str> {
    let mut corrections = 0;
    for k in 0..TICKS {
        let readings = readings_c.map(|r| {
            r.filter(|_| k == 0).map(|temp_c| TimedReading {
                result: Ok(Reading::new(temp_c)),
                sampled_at_us: *now_us,
            })
        });
        let inputs = NetworkInputs {
            currents_a,
            boundary_c,
            readings,
            now_us: *now_us,
            elapsed_us: 1000,
        };
        let mut out_copy = None;
        tick(&mut || {
            let o = observer.tick(state, &inputs);
            let steps = o.steps;
            out_copy = Some(*o);
            steps
        });
        let o = out_copy.ok_or("tick")?;
        corrections += u32::from(o.corrected);
        *checksum = checksum::fold(*checksum, &o);
        *now_us = now_us.wrapping_add(1000);
    }
    Ok(corrections)
}
