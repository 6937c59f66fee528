//! Writes how C and C++ projects find libnerve, beside the library the
//! build makes (`target/<profile>/`): `nerve.pc` for pkg-config and
//! `nerveConfig.cmake` (with `nerveConfigVersion.cmake`) for CMake's
//! `find_package(nerve)`, both pointing at this tree's `include/` (nerve.h,
//! nerve_types.h, nerve.hpp) and at that folder. `nerve new --lang c|cpp`
//! projects find nerve through them.
//!
//! A build script writes outside `OUT_DIR` here on purpose: the files must
//! sit where libnerve.so lands, which is `OUT_DIR`'s third parent
//! (`<target>/<profile>/build/nerve-agent-c-<hash>/out`). If that cannot be
//! done the build goes on and says so (a warning): only the two files are
//! missing then.

use std::path::{Path, PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if let Err(e) = write_files() {
        println!("cargo:warning=nerve.pc and nerveConfig.cmake were not written beside libnerve.so: {e}");
    }
}

fn write_files() -> Result<(), String> {
    let out = std::env::var_os("OUT_DIR").map(PathBuf::from).ok_or("cargo gave no OUT_DIR")?;
    let lib_dir = out.ancestors().nth(3).ok_or_else(|| format!("OUT_DIR {} has no third parent", out.display()))?;
    let manifest =
        std::env::var_os("CARGO_MANIFEST_DIR").map(PathBuf::from).ok_or("cargo gave no CARGO_MANIFEST_DIR")?;
    let include = manifest.join("include");
    let version = std::env::var("CARGO_PKG_VERSION").map_err(|e| format!("CARGO_PKG_VERSION: {e}"))?;
    write(&lib_dir.join("nerve.pc"), &pkg_config(lib_dir, &include, &version))?;
    write(&lib_dir.join("nerveConfig.cmake"), &cmake_config(&include, &manifest))?;
    write(&lib_dir.join("nerveConfigVersion.cmake"), &cmake_version(&version))
}

/// Writes `text` to `path` unless it holds it already (no needless change
/// of a file CMake or pkg-config watch).
fn write(path: &Path, text: &str) -> Result<(), String> {
    if std::fs::read_to_string(path).is_ok_and(|t| t == text) {
        return Ok(());
    }
    std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

fn pkg_config(lib_dir: &Path, include: &Path, version: &str) -> String {
    format!(
        "# nerve.pc: nerve's C API (libnerve), written by the build of nerve-agent-c\n\
         # (agent-sdk-c/build.rs) beside libnerve.so. Use it with\n\
         #   PKG_CONFIG_PATH={lib} pkg-config --cflags --libs nerve\n\
         libdir={lib}\n\
         includedir={include}\n\
         \n\
         Name: nerve\n\
         Description: nerve's agent SDK for C and C++ agents (nerve.h, nerve_types.h, nerve.hpp)\n\
         Version: {version}\n\
         Libs: -L${{libdir}} -Wl,-rpath,${{libdir}} -lnerve\n\
         Cflags: -I${{includedir}}\n",
        lib = lib_dir.display(),
        include = include.display(),
    )
}

/// A CMake string: quotes and backslashes escaped.
fn cmake_str(p: &Path) -> String {
    p.display().to_string().replace('\\', "\\\\").replace('"', "\\\"")
}

fn cmake_config(include: &Path, tree: &Path) -> String {
    format!(
        r#"# nerveConfig.cmake: nerve's C API (libnerve) for CMake, written by the
# build of nerve-agent-c (agent-sdk-c/build.rs) beside libnerve.so.
#   find_package(nerve REQUIRED)   # with -Dnerve_DIR=<this folder> or CMAKE_PREFIX_PATH
#   target_link_libraries(my_agent PRIVATE nerve::nerve)
# Sets nerve_INCLUDE_DIR (nerve.h, nerve_types.h, nerve.hpp) and nerve_LIB_DIR
# (this folder, for a build RPATH).
set(nerve_INCLUDE_DIR "{include}")
set(nerve_LIB_DIR "${{CMAKE_CURRENT_LIST_DIR}}")
if(NOT EXISTS "${{nerve_LIB_DIR}}/libnerve.so" OR NOT EXISTS "${{nerve_INCLUDE_DIR}}/nerve.h")
  set(nerve_FOUND FALSE)
  set(nerve_NOT_FOUND_MESSAGE
      "libnerve.so (${{nerve_LIB_DIR}}) or nerve.h (${{nerve_INCLUDE_DIR}}) is missing: build nerve's C API with `cargo build -p nerve-agent-c` in {tree}")
  return()
endif()
if(NOT TARGET nerve::nerve)
  add_library(nerve::nerve SHARED IMPORTED)
  set_target_properties(nerve::nerve PROPERTIES
    IMPORTED_LOCATION "${{nerve_LIB_DIR}}/libnerve.so"
    IMPORTED_NO_SONAME TRUE
    INTERFACE_INCLUDE_DIRECTORIES "${{nerve_INCLUDE_DIR}}")
endif()
"#,
        include = cmake_str(include),
        tree = cmake_str(tree),
    )
}

fn cmake_version(version: &str) -> String {
    format!(
        r#"# nerveConfigVersion.cmake: the version of the libnerve beside it ({version}); an
# exact match, or any when find_package asks for none.
set(PACKAGE_VERSION "{version}")
if(PACKAGE_FIND_VERSION AND NOT PACKAGE_FIND_VERSION VERSION_EQUAL PACKAGE_VERSION)
  set(PACKAGE_VERSION_COMPATIBLE FALSE)
else()
  set(PACKAGE_VERSION_COMPATIBLE TRUE)
  if(PACKAGE_FIND_VERSION VERSION_EQUAL PACKAGE_VERSION)
    set(PACKAGE_VERSION_EXACT TRUE)
  endif()
endif()
"#
    )
}
