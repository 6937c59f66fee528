//! `nerve iox2-config`: the iceoryx2 configuration of this robot, for
//! iceoryx2's own tools. A robot is an isolated iceoryx2 world (its own
//! file prefix under nerve's root path); `iox2` (`cargo install
//! iceoryx2-cli`) sees it once its configuration says so:
//!
//! ```sh
//! mkdir -p config && nerve iox2-config > config/iceoryx2.toml
//! iox2 service list            # the robot's ports, control services, events
//! iox2 service details nerve/ROBOT/AGENT/PORT   # attributes: nerve.type, nerve.fingerprint, ...
//! ```
//!
//! (`iox2` reads `config/iceoryx2.toml` in the folder it runs in, then
//! `~/.config/iceoryx2/iceoryx2.toml`.)

use agent_sdk::World;
use anyhow::{Context as _, Result};
use std::process::ExitCode;

pub fn iox2_config(world: &World) -> Result<ExitCode> {
    let text = toml::to_string(world.config()).context("cannot write the iceoryx2 configuration as TOML")?;
    println!(
        "# iceoryx2 configuration of nerve robot {robot}: save as config/iceoryx2.toml\n\
         # where iceoryx2's tools run (`iox2 service list`), or as ~/.config/iceoryx2/iceoryx2.toml\n{text}",
        robot = world.robot()
    );
    Ok(ExitCode::SUCCESS)
}
