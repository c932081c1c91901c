//! What the codegen round-trip tests share.

use std::path::Path;

/// Panics unless the committed `file` (from the workspace root) is
/// `fresh`, the generator's text today, naming `command`, which writes it.
pub fn assert_committed_is_fresh(file: &str, command: &str, fresh: &str) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(file);
    let committed =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        committed == fresh,
        "{file} is stale; regenerate with: {command}"
    );
}
