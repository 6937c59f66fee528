//! `nerve new NAME --lang c` and `--lang cpp`: a CMake project of an agent
//! on nerve's C API (libnerve, `agent-sdk-c/`): the agent (`NAME.c` on
//! `nerve.h` and `nerve_types.h`, or `NAME.cpp` on `nerve.hpp`), its test
//! on the C test harness (`test_NAME.c`, `test_NAME.cpp`), a
//! `CMakeLists.txt` that finds nerve with `find_package(nerve)` (the
//! `nerveConfig.cmake` the build of libnerve writes beside it, in the
//! nerve tree this `nerve` was built from) and adds `ctest`s of what the
//! agent declares and of its test, a launch file that wires it to a
//! ticker, and a README.
//! `cmake -S . -B build && cmake --build build` then `nerve launch
//! launch.toml` work on it as made. The templates are `new/native/*.in`,
//! built into the `nerve` program.

use super::{Drive, drive_words, module_name};
use anyhow::{Context as _, Result};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const CMAKE: &str = include_str!("native/CMakeLists.txt.in");
const AGENT_C: &str = include_str!("native/agent.c.in");
const AGENT_CPP: &str = include_str!("native/agent.cpp.in");
const TEST_C: &str = include_str!("native/test.c.in");
const TEST_CPP: &str = include_str!("native/test.cpp.in");
const LAUNCH_TOML: &str = include_str!("native/launch.toml.in");
const README_MD: &str = include_str!("native/README.md.in");
const GITIGNORE: &str = include_str!("native/gitignore.in");

/// C or C++.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Native {
    C,
    Cpp,
}

/// Where a C project finds nerve: its headers and libnerve.so.
#[derive(Debug, Clone)]
pub(super) struct Found {
    include: PathBuf,
    lib: PathBuf,
}

/// nerve's C headers in tree `nerve`, and the folder of its libnerve.so:
/// beside this `nerve` program when built there (a workspace build puts
/// both in one folder), else `target` (nerve's target folder)/debug.
pub(super) fn find(nerve: &Path, target: &Path) -> Found {
    let include = nerve.join("agent-sdk-c").join("include");
    let beside = std::env::current_exe().ok().and_then(|e| e.parent().map(Path::to_path_buf));
    let lib = match beside {
        Some(dir) if dir.join("libnerve.so").is_file() => dir,
        _ => target.join("debug"),
    };
    Found { include, lib }
}

/// Writes the project into `root` (which does not exist yet).
pub(super) fn new_native(
    name: &str,
    drive: &Drive,
    root: &Path,
    lang: Native,
    nerve: &Path,
    found: &Found,
) -> Result<ExitCode> {
    let files = render(name, drive, lang, nerve, found);
    std::fs::create_dir_all(root).with_context(|| format!("cannot create {}", root.display()))?;
    for (path, text) in &files {
        let p = root.join(path);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
    }
    let words = if lang == Native::C { "C" } else { "C++" };
    println!("made {words} agent {name} ({}) in {}:", drive_words(drive), root.display());
    for (path, _) in &files {
        println!("  {path}");
    }
    if !found.lib.join("libnerve.so").is_file() || !found.lib.join("nerveConfig.cmake").is_file() {
        println!(
            "note: {} has no libnerve.so or nerveConfig.cmake yet: build nerve's C API first (cargo build -p nerve-agent-c in {})",
            found.lib.display(),
            nerve.display()
        );
    }
    println!(
        "next:\n  cd {}\n  cmake -S . -B build && cmake --build build\n  (cd build && ctest)\n  nerve launch launch.toml\n  nerve echo {name}/out --count 3",
        root.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The project's files, by path in it.
pub(super) fn render(name: &str, drive: &Drive, lang: Native, nerve: &Path, found: &Found) -> Vec<(String, String)> {
    let cname = module_name(name);
    let (lang_flag, cmake_lang, ext, std_prop, template, test_template) = match lang {
        Native::C => ("c", "C", "c", "C_STANDARD 11", AGENT_C, TEST_C),
        Native::Cpp => ("cpp", "CXX", "cpp", "CXX_STANDARD 17", AGENT_CPP, TEST_CPP),
    };
    let source = format!("{cname}.{ext}");
    let test_source = format!("test_{cname}.{ext}");
    let std_line = format!("set_property(TARGET {name} test_{cname} PROPERTY {std_prop})");
    let (what, period_ns, period_words, c_step, cpp_step, period_line, task_words) = match drive {
        Drive::Event => (
            "an event-driven agent that sends every tick arriving on `in` on `out`, its sequence number multiplied by the parameter `gain`.".to_owned(),
            "0".to_owned(),
            "0: event-driven, woken by every sample on `in`".to_owned(),
            "  /* every waiting sample, read in place in shared memory */\n  for (;;) {\n    const void *data = NULL;\n    size_t len = 0;\n    nerve_status s = nerve_take(ctx, a->in, &data, &len);\n    if (s == NERVE_NO_SAMPLE) {\n      return 0;\n    }\n    if (s != NERVE_OK) {\n      return fail(\"take\");\n    }\n    if (send_out(ctx, a, data, gain) != 0) {\n      return 1;\n    }\n  }".to_owned(),
            "        // every waiting sample, read in place in shared memory\n        while (const nerve_Tick *t = c.take(in)) {\n          c.send(out, transform(*t, g));\n        }".to_owned(),
            String::new(),
            "event-driven: woken by every sample on `in`".to_owned(),
        ),
        Drive::Periodic(p, d) => (
            format!(
                "a periodic agent that, every {p}, sends the newest tick that arrived on `in` on `out`, its sequence number multiplied by the parameter `gain`."
            ),
            format!("{}u", d.as_nanos()),
            format!("every {p} by default; `--period`, a launch file's `period` and `nerve rate` change it"),
            "  /* the newest sample since the last cycle, if any */\n  const void *data = NULL;\n  size_t len = 0;\n  nerve_status s = nerve_latest(ctx, a->in, &data, &len);\n  if (s == NERVE_NO_SAMPLE) {\n    return 0;\n  }\n  if (s != NERVE_OK) {\n    return fail(\"latest\");\n  }\n  return send_out(ctx, a, data, gain);".to_owned(),
            "        // the newest sample since the last cycle, if any\n        if (const nerve_Tick *t = c.latest(in)) {\n          c.send(out, transform(*t, g));\n        }".to_owned(),
            format!("period = \"{p}\"\n"),
            format!("periodic, every {p} by default"),
        ),
    };
    // CMake's strings: quotes and backslashes escaped
    let cmake_path = |p: &Path| p.display().to_string().replace('\\', "\\\\").replace('"', "\\\"");
    let fill = |t: &str| {
        t.replace("{{what}}", &what)
            .replace("{{period_ns}}", &period_ns)
            .replace("{{period_words}}", &period_words)
            .replace("{{c_step}}", &c_step)
            .replace("{{cpp_step}}", &cpp_step)
            .replace("{{period_line}}", &period_line)
            .replace("{{task_words}}", &task_words)
            .replace("{{lang}}", lang_flag)
            .replace("{{cmake_lang}}", cmake_lang)
            .replace("{{source}}", &source)
            .replace("{{test_source}}", &test_source)
            .replace("{{std_line}}", &std_line)
            .replace("{{include}}", &cmake_path(&found.include))
            .replace("{{libdir}}", &cmake_path(&found.lib))
            .replace("{{nerve}}", &nerve.display().to_string())
            .replace("{{cname}}", &cname)
            .replace("{{name}}", name)
    };
    vec![
        (source.clone(), fill(template)),
        (test_source.clone(), fill(test_template)),
        ("CMakeLists.txt".into(), fill(CMAKE)),
        ("launch.toml".into(), fill(LAUNCH_TOML)),
        ("README.md".into(), fill(README_MD)),
        (".gitignore".into(), fill(GITIGNORE)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_placeholder_is_filled_in_c_and_cpp() {
        let found = Found { include: "/src/nerve/agent-sdk-c/include".into(), lib: "/src/nerve/target/debug".into() };
        for drive in [Drive::Event, Drive::Periodic("50ms".into(), std::time::Duration::from_millis(50))] {
            for lang in [Native::C, Native::Cpp] {
                for (path, text) in render("my-agent", &drive, lang, Path::new("/src/nerve"), &found) {
                    assert!(!text.contains("{{"), "{path} keeps a placeholder:\n{text}");
                }
            }
        }
    }
}
