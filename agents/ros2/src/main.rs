//! `nerve-ros2`: the `ros2` agent (see the library's documentation and
//! docs/ros2.md).

fn main() -> std::process::ExitCode {
    agent_sdk::run::<nerve_ros2::Ros2>()
}
