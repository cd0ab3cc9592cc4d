//! `.usdc` by converting our `.usda` with usd-core's `pxr` in a Python process.
//!
//! The crate format is only written faithfully by USD itself (no Rust writer that usd-core
//! 26.11 accepts builds with our toolchain), so we ask the reference implementation.
//! The Python executable is `$BLENDSIM_PYTHON`, or `python3`.
//!
//! Starting Python and importing `pxr` costs about 0.3 s of CPU, more than converting a small
//! layer, so one [`Converter`] process converts every file of a bake: it imports `pxr` once,
//! then reads one JSON line `["in.usda", "out.usdc"]` per file from its stdin and answers
//! `[true, ""]` or `[false, "message"]` on its stdout. A bake can start it before the solve so
//! the import overlaps the solve (see `stages::Bake::files`). The bytes are the same as one
//! process per file: each layer is opened, exported and released on its own.

use std::ffi::{OsStr, OsString};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{ChildStdin, ChildStdout, Command, Stdio};
use std::thread::JoinHandle;

use crate::error::{Error, Result};
use crate::interrupt::ChildGuard;

/// Exit code of the script when `pxr` cannot be imported.
const NO_PXR: i32 = 3;

const SCRIPT: &str = "\
import sys, json
try:
    from pxr import Sdf
except ImportError as e:
    print(e, file=sys.stderr)
    sys.exit(3)
for line in sys.stdin:
    usda, usdc = json.loads(line)
    try:
        layer = Sdf.Layer.FindOrOpen(usda)
        ok = layer is not None and layer.Export(usdc)
        message = '' if ok else 'Sdf.Layer.Export returned false'
    except Exception as e:
        lines = [l.strip() for l in str(e).splitlines() if l.strip()]
        ok, message = False, lines[-1] if lines else type(e).__name__
    layer = None
    print(json.dumps([bool(ok), message]), flush=True)
";

const FIX: &str = "pip install usd-core (or set BLENDSIM_PYTHON to a Python that has it)";

/// A running Python with `pxr` imported (or importing), converting one file per request.
/// Dropped: its stdin closes and the process, whose loop then ends, is waited for; one that
/// never converted anything (the bake failed first) is killed instead of waiting for its import.
pub struct Converter {
    python: OsString,
    /// `None` when Python could not be started: the error is given at the first conversion,
    /// naming the file the caller wanted.
    running: Option<Running>,
}

struct Running {
    child: ChildGuard,
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
    /// Drains stderr (USD's warnings) so a chatty layer cannot block the pipe.
    stderr: Option<JoinHandle<Vec<u8>>>,
    /// Whether a conversion was asked for.
    used: bool,
}

impl Converter {
    /// Start `$BLENDSIM_PYTHON` (or `python3`); never fails here, see [`Converter::convert`].
    pub fn start() -> Converter {
        Converter::start_with(&std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| OsString::from("python3")))
    }

    /// [`Converter::start`] with an explicit Python executable.
    pub(crate) fn start_with(python: &OsStr) -> Converter {
        // Started so that it dies with us (signal or kill), see `interrupt::spawn`.
        let running = crate::interrupt::spawn(
            Command::new(python).arg("-c").arg(SCRIPT).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped()),
        )
        .ok()
        .map(|mut child| {
            let stdin = child.child().stdin.take();
            let stdout = BufReader::new(child.child().stdout.take().expect("piped stdout"));
            let mut pipe = child.child().stderr.take().expect("piped stderr");
            let stderr = std::thread::spawn(move || {
                let mut bytes = Vec::new();
                let _ = pipe.read_to_end(&mut bytes);
                bytes
            });
            Running { child, stdin, stdout, stderr: Some(stderr), used: false }
        });
        Converter { python: python.to_owned(), running }
    }

    /// Convert `usda` to `usdc`; a clear error names the fix when Python or `pxr` is missing.
    pub fn convert(&mut self, usda: &Path, usdc: &Path) -> Result<()> {
        let py = self.python.to_string_lossy().into_owned();
        let Some(running) = self.running.as_mut() else {
            // Start again only to get the operating system's reason.
            let e = Command::new(&self.python).arg("-c").arg("").stdin(Stdio::null()).output().err();
            let reason = e.map_or("it did not start".to_string(), |e| e.to_string());
            return Err(Error::in_file(usdc, format!("cannot run {py} to write the usdc file: {reason}"), FIX));
        };
        let (Some(a), Some(c)) = (usda.to_str(), usdc.to_str()) else {
            return Err(Error::in_file(usdc, "the path is not valid UTF-8, which usd-core's Python API needs", "write into a folder whose path is UTF-8"));
        };
        if !running.used {
            // The interruption tests stop here: in the export, with Python running.
            crate::interrupt::pause_point("usdc", &format!("(pid {})", running.child.id()));
            running.used = true;
        }
        let mut request = serde_json::to_string(&[a, c]).expect("strings serialize");
        request.push('\n');
        let sent = running.stdin.as_mut().map(|s| s.write_all(request.as_bytes()).and_then(|()| s.flush()));
        let mut answer = String::new();
        let answered = matches!(sent, Some(Ok(()))) && running.stdout.read_line(&mut answer).is_ok_and(|n| n > 0);
        if answered {
            return match serde_json::from_str::<(bool, String)>(&answer) {
                Ok((true, _)) if usdc.is_file() => Ok(()),
                Ok((_, message)) => Err(failed(usda, usdc, if message.is_empty() { "no file written" } else { &message })),
                Err(_) => Err(failed(usda, usdc, answer.trim())),
            };
        }
        // The process ended: it could not import pxr, or crashed. It is of no further use.
        let mut running = self.running.take().expect("checked above");
        drop(running.stdin.take());
        let status = running.child.child().wait();
        let stderr = running.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        let stderr = String::from_utf8_lossy(&stderr);
        let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim().to_string();
        Err(match status {
            Ok(s) if s.code() == Some(NO_PXR) => Error::in_file(usdc, format!("{py} cannot import usd-core's pxr module ({last})"), FIX),
            Ok(s) => failed(usda, usdc, &format!("{s}: {last}")),
            Err(e) => failed(usda, usdc, &e.to_string()),
        })
    }
}

fn failed(usda: &Path, usdc: &Path, why: &str) -> Error {
    Error::in_file(
        usdc,
        format!("usd-core failed to convert {} ({why})", usda.display()),
        "check that usd-core opens the .usda file (python3 -c \"from pxr import Usd; Usd.Stage.Open('FILE')\")",
    )
}

impl Drop for Converter {
    fn drop(&mut self) {
        if let Some(mut running) = self.running.take() {
            // End of input: the script's loop ends and Python exits on its own.
            drop(running.stdin.take());
            if running.used {
                let _ = running.child.child().wait();
            }
            // Otherwise the guard kills it (and its process group) and reaps it.
            drop(running.child);
            if let Some(h) = running.stderr.take() {
                let _ = h.join();
            }
        }
    }
}

/// Convert one `usda` to `usdc` in a Python process of its own.
#[cfg(test)]
pub(crate) fn convert_with(python: &OsStr, usda: &Path, usdc: &Path) -> Result<()> {
    Converter::start_with(python).convert(usda, usdc)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("blendsim-usdc-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn missing_python_names_the_fix() {
        let d = scratch("missing");
        let e = convert_with(OsStr::new("/nonexistent/python3"), &d.join("a.usda"), &d.join("a.usdc")).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("a.usdc: cannot run /nonexistent/python3"), "{s}");
        assert!(s.contains("(fix: pip install usd-core"), "{s}");
        assert!(!s.contains('\n'));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn python_without_pxr_names_the_fix() {
        // `python3 -I -S` is a Python without site-packages, hence without usd-core.
        let d = scratch("nopxr");
        let wrapper = d.join("python-without-site");
        std::fs::write(&wrapper, "#!/bin/sh\nexec python3 -I -S \"$@\"\n").unwrap();
        std::process::Command::new("chmod").arg("+x").arg(&wrapper).status().unwrap();
        let e = convert_with(wrapper.as_os_str(), &d.join("a.usda"), &d.join("a.usdc")).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("cannot import usd-core's pxr module (No module named 'pxr')"), "{s}");
        assert!(s.contains("(fix: pip install usd-core"), "{s}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn converts_a_layer_that_usd_reads_back() {
        let d = scratch("convert");
        let (a, c) = (d.join("x.usda"), d.join("x.usdc"));
        std::fs::write(&a, "#usda 1.0\n(\n    defaultPrim = \"x\"\n)\n\ndef Xform \"x\"\n{\n}\n").unwrap();
        convert_with(OsStr::new("python3"), &a, &c).unwrap();
        assert_eq!(&std::fs::read(&c).unwrap()[..8], b"PXR-USDC");
        std::fs::write(&a, "#usda 1.0\ndef Xform \"x\" {\n").unwrap();
        let e = convert_with(OsStr::new("python3"), &a, &d.join("bad.usdc")).unwrap_err().to_string();
        assert!(e.contains("usd-core failed to convert"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// One process converts a series of layers, a bad one in the middle included, into the
    /// bytes one process per file writes.
    #[test]
    fn one_process_converts_many_files_as_one_process_each() {
        let d = scratch("many");
        let mut converter = Converter::start_with(OsStr::new("python3"));
        for i in 0..3 {
            let (a, c) = (d.join(format!("x{i}.usda")), d.join(format!("x{i}.usdc")));
            std::fs::write(&a, format!("#usda 1.0\n(\n    defaultPrim = \"x\"\n)\n\ndef Xform \"x\"\n{{\n    double3 xformOp:translate = ({i}, 0, 0)\n}}\n")).unwrap();
            converter.convert(&a, &c).unwrap();
            let alone = d.join(format!("alone{i}.usdc"));
            convert_with(OsStr::new("python3"), &a, &alone).unwrap();
            assert_eq!(std::fs::read(&c).unwrap(), std::fs::read(&alone).unwrap(), "file {i}");
            if i == 1 {
                std::fs::write(d.join("bad.usda"), "#usda 1.0\ndef Xform \"x\" {\n").unwrap();
                let e = converter.convert(&d.join("bad.usda"), &d.join("bad.usdc")).unwrap_err().to_string();
                assert!(e.contains("bad.usdc: usd-core failed to convert") && !e.contains('\n'), "{e}");
            }
        }
        drop(converter);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
