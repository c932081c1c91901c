//! The simulated board, shared with the RTIC example
//! (`examples/support/sim_board.rs`): a product's drivers go here.

#[path = "../../support/sim_board.rs"]
mod sim;
pub use sim::*;
