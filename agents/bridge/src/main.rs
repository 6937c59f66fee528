//! `nerve-bridge`: the bridge agent carrying every built-in payload type.

fn main() -> std::process::ExitCode {
    nerve_bridge::main_with(nerve_bridge::Types::builtin())
}
