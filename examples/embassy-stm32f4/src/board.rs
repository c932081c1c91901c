//! The simulated board, shared with the RTIC example
//! (`examples/support/sim_board.rs`): a product's drivers go here.

// Shared with the RTIC example, whose power cycles use more of it.
#[allow(dead_code)]
#[path = "../../support/sim_board.rs"]
mod sim;
pub use sim::*;
