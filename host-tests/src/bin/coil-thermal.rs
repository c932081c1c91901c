//! The `coil-thermal` host tool: see `coil-thermal --help`.

fn main() -> std::process::ExitCode {
    coil_thermal_host::cli::main_entry()
}
