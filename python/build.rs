//! Empty on purpose: this package's `[build-dependencies]` exist only so that
//! cargo resolves the features of what runs at build time as it does for the
//! whole workspace (see Cargo.toml), and cargo builds build-dependencies only
//! for a package that has a build script.

fn main() {}
