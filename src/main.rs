//! `mdlod`: the command-line program. Argument parsing and progress output only; the work
//! lives in the library crates.

/// `println!` for the commands' output, shadowing std's in this crate: when the reader
/// of a pipe has gone (`mdlod info frame.mdlod | head -1`), later output is dropped and
/// the command finishes its work (files it writes, working files it removes), instead of
/// std's panic ("failed printing to stdout") in the middle of it.
macro_rules! println {
    () => {
        $crate::print_line(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::print_line(format_args!($($arg)*))
    };
}

mod bus_error;
mod commands;
mod interrupt;
mod progress;

/// Set once standard output has failed: nothing more is written to it.
static OUTPUT_GONE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Set when it failed otherwise than by its reader leaving (a full disk): the command
/// then ends with a failure once its work is done.
static OUTPUT_FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Set by a command's `--json`: standard output holds the one JSON object the command
/// ends with ([`print_json`]); its lines of text go to standard error, and its notes into
/// that object too.
static JSON_OUTPUT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// Set by `info --json`, which prints its JSON itself: a failure still ends with the
/// one object `{"ok": false, "error"}` on standard output, as with [`JSON_OUTPUT`].
static JSON_ERRORS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Turns on JSON errors alone (see [`JSON_ERRORS`]).
fn json_errors() {
    JSON_ERRORS.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Whether a failure is reported as a JSON object on standard output too.
fn json_failures() -> bool {
    use std::sync::atomic::Ordering::Relaxed;
    JSON_OUTPUT.load(Relaxed) || JSON_ERRORS.load(Relaxed)
}

/// Set once a command's JSON result has been written ([`print_json`]; not by the parts
/// [`print_json_part`] writes).
static JSON_PRINTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether this run has written a JSON object yet.
fn json_printed() -> bool {
    JSON_PRINTED.load(std::sync::atomic::Ordering::Relaxed)
}

/// The notes said in JSON mode, for the object's `notes`.
static NOTES: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// Turns on JSON mode (see [`JSON_OUTPUT`]).
fn json_output() {
    JSON_OUTPUT.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Writes `value` (an object) to standard output as one line of JSON, with the notes
/// said since the last as its `notes`: the command's result, after which a failure
/// prints no object of its own.
fn print_json(value: serde_json::Value) {
    write_json(value, true);
}

/// [`print_json`] of one part of a result (an image of a movie or a turntable): a
/// failure after it still ends with its `{"ok": false, "error"}` object.
fn print_json_part(value: serde_json::Value) {
    write_json(value, false);
}

fn write_json(mut value: serde_json::Value, result: bool) {
    use std::io::Write;
    if let serde_json::Value::Object(map) = &mut value {
        let notes = std::mem::take(&mut *NOTES.lock().unwrap_or_else(|e| e.into_inner()));
        // (Notes the object gives itself, `info`'s, come first.)
        match map.get_mut("notes").and_then(|n| n.as_array_mut()) {
            Some(own) => own.extend(notes.into_iter().map(Into::into)),
            None => {
                map.insert("notes".into(), notes.into());
            }
        }
    }
    // The flag is set under the lock of standard output, which the Ctrl-C handler
    // holds while it decides whether to print an object of its own: a run interrupted
    // as it prints its result gives one object, not two.
    let mut out = std::io::stdout().lock();
    if result {
        JSON_PRINTED.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    if let Err(e) = writeln!(out, "{value}") {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("error: writing to standard output: {e}");
            OUTPUT_FAILED.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

/// Writes a line of output (see `println!` above).
fn print_line(line: std::fmt::Arguments) {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if JSON_OUTPUT.load(Ordering::Relaxed) {
        let text = line.to_string();
        // (A note's line starts with it, after its indent or the path it is about.)
        let note = text
            .trim_start()
            .strip_prefix("note: ")
            .or_else(|| text.split_once(": note: ").map(|(_, n)| n));
        if let Some(note) = note {
            NOTES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(note.to_string());
        }
        eprintln!("{text}");
        return;
    }
    if OUTPUT_GONE.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(line).and_then(|()| out.write_all(b"\n")) {
        OUTPUT_GONE.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("error: writing to standard output: {e}");
            OUTPUT_FAILED.store(true, Ordering::Relaxed);
        }
    }
}

/// jemalloc instead of the system allocator. A conversion builds chunk after chunk with
/// the same large buffers; glibc returns every block over 32 MiB to the kernel when it is
/// freed, so each chunk faulted in and zeroed its memory afresh (a tenth of a 2×10^8
/// conversion's time). jemalloc reuses it, in transparent huge pages where the kernel
/// allows them; its settings are in `.cargo/config.toml`.
#[cfg(all(target_os = "linux", not(target_env = "musl")))]
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "mdlod",
    version,
    about = "Level-of-detail conversion and rendering for huge particle simulations",
    long_about = "mdlod converts molecular-dynamics, SPH and n-body dumps once into a \
                  level-of-detail .mdlod file (a PCA-split cluster hierarchy with quantized \
                  relative coordinates, laid out for memory mapping)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Convert(commands::convert::Args),
    Batch(commands::batch::Args),
    Info(commands::info::Args),
    Verify(commands::verify::Args),
    // (Boxed: its options make it far larger than the other commands'.)
    Render(Box<commands::render::Args>),
    Sample(commands::sample::Args),
    Shade(commands::shade::Args),
    Generate(commands::generate::Args),
    Demo(commands::demo::Args),
    View(commands::view::Args),
}

/// The options whose value is optional and so must follow an equals sign: a value given
/// after a space is read as the next argument (`--cell red frame.mdlod` makes `red` the
/// file and `frame.mdlod` unexpected). Where the argument clap found unexpected,
/// `unexpected`, is such a value or the one after it, the tip that says how to write it.
fn equals_tip(args: impl Iterator<Item = String>, unexpected: &str) -> Option<String> {
    const OPTIONAL_VALUE: &[&str] = &["--cell", "--legend-in-image"];
    let mut args: Vec<String> = args.collect();
    args.push(String::new());
    args.windows(3).find_map(|w| {
        let culprit = w[1] == unexpected || (!w[2].is_empty() && w[2] == unexpected);
        (OPTIONAL_VALUE.contains(&w[0].as_str()) && !w[1].starts_with('-') && culprit).then(|| {
            format!(
                "{} takes its value after an equals sign: {}={} (with a space, `{}` is read \
                 as the next argument)",
                w[0], w[0], w[1], w[1]
            )
        })
    })
}

/// A tip for a file to write given as a second input (`mdlod convert run.dump
/// run.mdlod`): the commands that write files take them after `-o`.
fn output_tip(mut args: impl Iterator<Item = String>, unexpected: &str) -> Option<String> {
    // What each command writes.
    const WRITES: &[(&str, &[&str])] = &[
        ("convert", &["mdlod"]),
        ("render", &["png", "svg"]),
        ("sample", &["sndf"]),
        ("shade", &["png"]),
    ];
    let command = args.next()?;
    let ext = std::path::Path::new(unexpected)
        .extension()?
        .to_string_lossy()
        .to_ascii_lowercase();
    let writes = WRITES.iter().find(|(c, _)| *c == command)?.1;
    (!unexpected.starts_with('-') && writes.contains(&ext.as_str())).then(|| {
        format!(
            "the file to write goes after -o: mdlod {command} ... -o {unexpected} (a second \
             file name alone is read as a second input)"
        )
    })
}

fn main() -> std::process::ExitCode {
    quiet_headless_gpu_probe();
    bus_error::install();
    let matches = match <Cli as clap::CommandFactory>::command().try_get_matches() {
        Ok(m) => m,
        Err(e) => {
            let unexpected = match e.get(clap::error::ContextKind::InvalidArg) {
                Some(clap::error::ContextValue::String(a)) => Some(a.clone()),
                _ => None,
            };
            let tip = unexpected
                .filter(|_| e.kind() == clap::error::ErrorKind::UnknownArgument)
                .and_then(|a| {
                    let args = || {
                        std::env::args_os()
                            .skip(1)
                            .map(|a| a.to_string_lossy().into_owned())
                    };
                    equals_tip(args(), &a).or_else(|| output_tip(args(), &a))
                })
                .or_else(|| decimal_comma_tip(&e));
            let _ = e.print();
            if let Some(tip) = &tip {
                eprintln!("\n  tip: {tip}");
            }
            // With --json, a command line that does not parse gives its object too (a
            // script reads standard output): `ok` false, with clap's error.
            let json = std::env::args_os()
                .skip(1)
                .take_while(|a| a != "--")
                .any(|a| a == "--json");
            if json && e.use_stderr() {
                // The message up to the usage, on one line (the missing arguments are
                // listed below its first line).
                let rendered = e.render().to_string();
                let message: Vec<&str> = rendered
                    .lines()
                    .take_while(|l| !l.trim().is_empty())
                    .map(str::trim)
                    .collect();
                let first = message.join(" ");
                let mut message = first.strip_prefix("error: ").unwrap_or(&first).to_string();
                if let Some(tip) = tip {
                    message.push_str(&format!(" (tip: {tip})"));
                }
                print_json(serde_json::json!({ "ok": false, "error": message }));
            }
            std::process::exit(e.exit_code());
        }
    };
    let cli = match <Cli as clap::FromArgMatches>::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    let result = match cli.command {
        Command::Convert(a) => commands::convert::run(a),
        Command::Batch(a) => matches
            .subcommand_matches("batch")
            .map_or(Ok(()), commands::batch::check_merge_options)
            .and_then(|()| commands::batch::run(a)),
        Command::Info(a) => commands::info::run(a),
        Command::Verify(a) => commands::verify::run(a),
        Command::Render(mut a) => {
            // (JSON mode first, so that the options refused here give their object too.)
            if a.json {
                json_output();
            }
            match matches.subcommand_matches("render") {
                Some(m) => commands::render::check_mode_options(&a, m).and_then(|()| {
                    commands::render::size_from_view(&mut a.camera, m);
                    commands::render::run(*a)
                }),
                None => commands::render::run(*a),
            }
        }
        Command::Sample(mut a) => {
            if let Some(m) = matches.subcommand_matches("sample") {
                commands::render::size_from_view(&mut a.camera, m);
            }
            commands::sample::run(a)
        }
        Command::Shade(a) => matches
            .subcommand_matches("shade")
            .map_or(Ok(()), commands::shade::check_options)
            .and_then(|()| commands::shade::run(a)),
        Command::Generate(a) => commands::generate::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::View(a) => commands::view::run(a),
    };
    match result {
        Ok(()) if OUTPUT_FAILED.load(std::sync::atomic::Ordering::Relaxed) => {
            std::process::ExitCode::FAILURE
        }
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            interrupt::defer_to_interrupt();
            // The chain of causes, without repeating one a message already includes
            // (library errors often show their source themselves).
            let mut message = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !message.contains(&c) {
                    message.push_str(": ");
                    message.push_str(&c);
                }
            }
            eprintln!("error: {message}");
            // With --json, a command that fails before its result (a damaged file, a held
            // lock, a bad input) gives one too: `ok` false, with the error.
            if json_failures() && !json_printed() {
                let mut value = serde_json::json!({ "ok": false, "error": message });
                // A batch that converted frames before it failed says how many.
                use mdlod_preprocess::batch::BatchError;
                let counts = e
                    .chain()
                    .find_map(|c| match c.downcast_ref::<BatchError>()? {
                        BatchError::NamesUnused {
                            converted, skipped, ..
                        } => Some(
                            serde_json::json!({ "converted": converted, "already_done": skipped }),
                        ),
                        // (Still missing, as an interrupted batch counts them.)
                        BatchError::Incomplete {
                            converted, todo, ..
                        } => Some(serde_json::json!({
                            "converted": converted,
                            "to_convert": todo.saturating_sub(*converted),
                        })),
                        _ => None,
                    });
                if let (Some(serde_json::Value::Object(counts)), Some(map)) =
                    (counts, value.as_object_mut())
                {
                    map.extend(counts);
                }
                print_json(value);
            }
            // Another batch holds the directory: 75 (EX_TEMPFAIL), so that a script can
            // tell "try again later" from a failure.
            let busy = e.chain().any(|c| {
                matches!(
                    c.downcast_ref::<mdlod_preprocess::batch::BatchError>(),
                    Some(mdlod_preprocess::batch::BatchError::Busy { .. })
                )
            });
            match busy {
                true => std::process::ExitCode::from(75),
                false => std::process::ExitCode::FAILURE,
            }
        }
    }
}

/// A number written with a decimal comma (`--zoom 1,5`, as a German or French locale
/// writes it), which the parser refuses as "invalid float literal": the tip gives it with
/// a point.
fn decimal_comma_tip(e: &clap::Error) -> Option<String> {
    if e.kind() != clap::error::ErrorKind::ValueValidation {
        return None;
    }
    let value = match e.get(clap::error::ContextKind::InvalidValue)? {
        clap::error::ContextValue::String(v) => v.clone(),
        _ => return None,
    };
    let pointed = value.replace(',', ".");
    (value.contains(',') && pointed.parse::<f64>().is_ok()).then(|| {
        let option = match e.get(clap::error::ContextKind::InvalidArg) {
            Some(clap::error::ContextValue::String(a)) => {
                a.split_whitespace().next().unwrap_or("").to_string()
            }
            _ => String::new(),
        };
        format!("numbers take a decimal point, not a comma: {option} {pointed}")
    })
}

/// Without a desktop session (`XDG_RUNTIME_DIR` unset: a batch job on a cluster node, an
/// ssh login), Mesa's Vulkan device-selection layer tries to reach a Wayland display to
/// learn which GPU drives the screen, and libwayland prints
/// `error: XDG_RUNTIME_DIR is invalid or not set in the environment.` twice before a
/// render that then succeeds. mdlod picks its adapter itself, so the layer is turned off
/// there (`NODEVICE_SELECT`, Mesa's switch for it), unless the user has set that switch.
/// Runs first in `main`, before any thread exists to read the environment concurrently.
fn quiet_headless_gpu_probe() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none()
        && std::env::var_os("NODEVICE_SELECT").is_none()
    {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}
