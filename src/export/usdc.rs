//! `.usdc` by converting our `.usda` with usd-core's `pxr` in a Python process.
//!
//! The crate format is only written faithfully by USD itself (no Rust writer that usd-core
//! 26.11 accepts builds with our toolchain), so we ask the reference implementation.
//! The Python executable is `$BLENDSIM_PYTHON`, or `python3`.

use std::ffi::{OsStr, OsString};
use std::path::Path;
use std::process::{Command, Stdio};

use crate::error::{Error, Result};

/// Exit code of the script when `pxr` cannot be imported.
const NO_PXR: i32 = 3;

const SCRIPT: &str = "\
import sys
try:
    from pxr import Sdf
except ImportError as e:
    print(e, file=sys.stderr)
    sys.exit(3)
layer = Sdf.Layer.FindOrOpen(sys.argv[1])
sys.exit(0 if layer is not None and layer.Export(sys.argv[2]) else 1)
";

const FIX: &str = "pip install usd-core (or set BLENDSIM_PYTHON to a Python that has it)";

/// Convert `usda` to `usdc`; a clear error names the fix when Python or `pxr` is missing.
pub fn convert(usda: &Path, usdc: &Path) -> Result<()> {
    let python = std::env::var_os("BLENDSIM_PYTHON").unwrap_or_else(|| OsString::from("python3"));
    convert_with(&python, usda, usdc)
}

/// [`convert`] with an explicit Python executable.
pub(crate) fn convert_with(python: &OsStr, usda: &Path, usdc: &Path) -> Result<()> {
    let py = python.to_string_lossy();
    // Started so that it dies with us (signal or kill), see `interrupt::spawn`.
    let cannot_run = |e: std::io::Error| Error::in_file(usdc, format!("cannot run {py} to write the usdc file: {e}"), FIX);
    let child = crate::interrupt::spawn(
        Command::new(python).arg("-c").arg(SCRIPT).arg(usda).arg(usdc).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()),
    )
    .map_err(cannot_run)?;
    crate::interrupt::pause_point("usdc", &format!("(pid {})", child.id()));
    let output = child.wait_with_output().map_err(cannot_run)?;
    if output.status.success() && usdc.is_file() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&output.stderr);
    let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim();
    Err(if output.status.code() == Some(NO_PXR) {
        Error::in_file(usdc, format!("{py} cannot import usd-core's pxr module ({last})"), FIX)
    } else {
        Error::in_file(
            usdc,
            format!("usd-core failed to convert {} ({}: {last})", usda.display(), output.status),
            "check that usd-core opens the .usda file (python3 -c \"from pxr import Usd; Usd.Stage.Open('FILE')\")",
        )
    })
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
}
