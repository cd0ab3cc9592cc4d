//! Diffuse textures of material groups (OBJ `map_Kd`) as the files carry them: embedded in a
//! glb, copied beside a USD file and referenced by a relative asset path.
//!
//! Only PNG and JPEG are carried: the two image formats glTF 2.0 core allows (USD's
//! UsdUVTexture reads them too). The format is told by the file's first bytes, not its name,
//! and the header is decoded (PNG up to its first image data, JPEG up to its first scan), so a
//! damaged file or one claiming more than [`MAX_SIDE`] pixels a side is refused here, not left
//! to the viewer.

use std::io::{BufRead, Cursor, Read, Seek, SeekFrom};
use std::path::Path;

use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// An image file's bytes and MIME type (`image/png` or `image/jpeg`).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// The file name it gets beside the USD files (see [`file_names`]).
    pub file_name: String,
    /// The image file, as read.
    pub bytes: Vec<u8>,
    /// `image/png` or `image/jpeg`.
    pub mime: &'static str,
}

/// The MIME type of PNG or JPEG bytes, from their signature.
pub(crate) fn mime_of(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some("image/png")
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        Some("image/jpeg")
    } else {
        None
    }
}

/// The largest width or height a texture may have: what most GPUs can sample (and glTF viewers
/// load); a header claiming more is damaged or would not display.
pub const MAX_SIDE: u32 = 16384;

/// The width, height and channels in an image's header, decoded by the PNG or JPEG decoder
/// (no pixels).
fn decoded_size<R: BufRead + Seek>(reader: R, mime: &str) -> std::result::Result<(u32, u32, u32), String> {
    if mime == "image/png" {
        let mut decoder = png::Decoder::new(reader);
        let (width, height, channels) =
            decoder.read_header_info().map(|info| (info.width, info.height, info.color_type.samples() as u32)).map_err(|e| e.to_string())?;
        // A size beyond the limit is its own message; below it the rest of the header is read.
        if width <= MAX_SIDE && height <= MAX_SIDE {
            decoder.read_info().map_err(|e| e.to_string())?;
        }
        Ok((width, height, channels))
    } else {
        let mut decoder = jpeg_decoder::Decoder::new(reader);
        decoder.read_info().map_err(|e| e.to_string())?;
        let info = decoder.info().ok_or("no frame header")?;
        Ok((u32::from(info.width), u32::from(info.height), info.pixel_format.pixel_bytes() as u32))
    }
}

/// The MIME type of an image that can be a texture, from its header; otherwise what is wrong
/// with it, worded to follow "the file", and the fix. Reads the header only.
pub fn inspect<R: BufRead + Seek>(mut reader: R) -> std::result::Result<&'static str, (String, String)> {
    let mut head = Vec::with_capacity(8);
    let read = reader.by_ref().take(8).read_to_end(&mut head).and_then(|_| reader.seek(SeekFrom::Start(0)));
    let damaged = |e: String| (e, "re-save the image from an image editor, or re-export it".to_string());
    read.map_err(|e| damaged(format!("cannot be read: {e}")))?;
    let mime = mime_of(&head).ok_or_else(|| {
        (
            "is not a PNG or JPEG image (glTF carries only those)".to_string(),
            "convert it to PNG (or JPEG) and point the .mtl's map_Kd at the converted file".to_string(),
        )
    })?;
    let kind = &mime["image/".len()..];
    let (width, height, _) = decoded_size(reader, mime).map_err(|e| damaged(format!("is not a readable {kind} image: {e}")))?;
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err((
            format!("is a {kind} image of {width} x {height} pixels, over the {MAX_SIDE} a side that most GPUs can sample"),
            format!("scale the image down to at most {MAX_SIDE} pixels a side"),
        ));
    }
    Ok(mime)
}

/// Per group, the name its texture gets in the output folder: the texture's own file name,
/// with `_2`, `_3`... before the extension when two different files share a name. Groups
/// sharing one file share one name. Deterministic (depends on the paths only).
pub fn file_names(textures: &[Option<String>]) -> Vec<Option<String>> {
    let mut given: Vec<(String, String)> = Vec::new(); // (path, name)
    textures
        .iter()
        .map(|t| {
            let path = t.as_ref()?;
            if let Some((_, name)) = given.iter().find(|(p, _)| p == path) {
                return Some(name.clone());
            }
            // `@` would end a USD asset path.
            let file = Path::new(path).file_name().map_or_else(|| "texture".into(), |f| f.to_string_lossy().replace('@', "_"));
            let (stem, ext) = match file.rfind('.') {
                Some(i) if i > 0 => (&file[..i], &file[i..]),
                _ => (&file[..], ""),
            };
            let mut name = file.clone();
            let mut k = 2;
            while given.iter().any(|(_, n)| *n == name) {
                name = format!("{stem}_{k}{ext}");
                k += 1;
            }
            given.push((path.clone(), name.clone()));
            Some(name)
        })
        .collect()
}

/// Copies of a texture file's bytes an export holds at once: the file as read, and the glb
/// buffers the blendshape and full-frame files are assembled in (a 600 MB texture peaked at
/// 2.47 GB, about four).
pub const FILE_COPIES: f64 = 4.0;

/// The memory a texture needs, estimated before it is read: [`FILE_COPIES`] of its file, and
/// its pixels once decoded (width x height x channels from the header), which a viewer of the
/// output needs and a header claiming far more than the file holds betrays.
fn check_memory(path: &Path, budget: &Budget) -> Result<()> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, &e, "read the texture a material's map_Kd names"))?;
    let bytes = file.metadata().map_err(|e| Error::io(path, &e, "measure the texture"))?.len() as f64;
    let mut reader = std::io::BufReader::new(file);
    let mut head = Vec::with_capacity(8);
    let _ = reader.by_ref().take(8).read_to_end(&mut head);
    let pixels = match (mime_of(&head), reader.seek(SeekFrom::Start(0))) {
        // A header over MAX_SIDE (or unreadable) is `inspect`'s error, with its own message.
        (Some(mime), Ok(_)) => decoded_size(reader, mime)
            .ok()
            .filter(|&(w, h, _)| w <= MAX_SIDE && h <= MAX_SIDE)
            .map_or(0.0, |(w, h, c)| w as f64 * h as f64 * c as f64),
        _ => 0.0, // `inspect` reports it
    };
    budget
        .check(
            FILE_COPIES * bytes + pixels,
            &format!(
                "the texture {} ({:.1} MB, {:.1} MB of pixels decoded)",
                path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
                bytes / 1e6,
                pixels / 1e6
            ),
            "scale the texture down or save it compressed (PNG or JPEG)",
        )
        .map_err(|e| e.with_path(path))
}

/// Read every group's texture (`None` for groups without one), each first checked against the
/// memory `budget` (`check_memory`). Errors name the image file.
pub fn load(textures: &[Option<String>], budget: &Budget) -> Result<Vec<Option<Texture>>> {
    let names = file_names(textures);
    textures
        .iter()
        .zip(names)
        .map(|(path, name)| {
            let (Some(path), Some(file_name)) = (path, name) else { return Ok(None) };
            check_memory(Path::new(path), budget)?;
            let bytes = crate::support::input::read_bytes(Path::new(path), "the texture a material's map_Kd names")?;
            let mime = inspect(Cursor::new(&bytes)).map_err(|(problem, fix)| Error::in_file(path, problem, fix))?;
            Ok(Some(Texture { file_name, bytes, mime }))
        })
        .collect()
}

/// A 1 x 1 grey PNG, its IHDR claiming `width` x `height` (CRC made to match): for tests.
#[cfg(test)]
pub(crate) fn png_claiming(width: u32, height: u32) -> Vec<u8> {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend((data.len() as u32).to_be_bytes());
        let body = [kind, data].concat();
        out.extend_from_slice(&body);
        out.extend(crc32(&body).to_be_bytes());
    };
    chunk(b"IHDR", &[&width.to_be_bytes()[..], &height.to_be_bytes(), &[8, 0, 0, 0, 0]].concat());
    // zlib of the one row `0 128` in a stored block.
    chunk(b"IDAT", &[0x78, 0x01, 0x01, 0x02, 0x00, 0xfd, 0xff, 0x00, 0x80, 0x00, 0x82, 0x00, 0x81]);
    chunk(b"IEND", &[]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_file_names_made_unique() {
        let t = |p: &str| Some(p.to_string());
        let names = file_names(&[t("/a/wood.png"), None, t("/b/wood.png"), t("/a/wood.png"), t("/c/wood.png"), t("/d/noext")]);
        let s = |n: &str| Some(n.to_string());
        assert_eq!(names, vec![s("wood.png"), None, s("wood_2.png"), s("wood.png"), s("wood_3.png"), s("noext")]);
    }

    #[test]
    fn headers_are_decoded_and_their_size_bounded() {
        assert_eq!(decoded_size(Cursor::new(png_claiming(1, 1)), "image/png").map(|(w, h, _)| (w, h)), Ok((1, 1)));
        assert_eq!(decoded_size(Cursor::new(png_claiming(1_000_000, 1_000_000)), "image/png").map(|(w, h, _)| (w, h)), Ok((1_000_000, 1_000_000)));
        let garbage = [&b"\x89PNG\r\n\x1a\n"[..], &[0x5a; 40]].concat();
        assert!(decoded_size(Cursor::new(&garbage), "image/png").is_err());
        let mut bad_crc = png_claiming(2, 2);
        bad_crc[29] ^= 1;
        assert!(decoded_size(Cursor::new(&bad_crc), "image/png").is_err());
        assert!(decoded_size(Cursor::new([0xff, 0xd8, 0xff, 0xe0, 0, 16, b'J', b'F']), "image/jpeg").is_err());

        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let load_one = |name: &str, bytes: &[u8]| {
            let p = dir.join(name);
            std::fs::write(&p, bytes).unwrap();
            load(&[Some(p.to_string_lossy().into_owned())], &Budget::default()).map(|t| t[0].as_ref().map(|t| t.mime))
        };
        assert_eq!(load_one("ok.png", &png_claiming(1, 1)), Ok(Some("image/png")));
        let e = load_one("big.png", &png_claiming(1_000_000, 1_000_000)).unwrap_err().to_string();
        assert!(e.contains("big.png: is a png image of 1000000 x 1000000 pixels, over the 16384 a side"), "{e}");
        let e = load_one("edge.png", &png_claiming(16385, 1)).unwrap_err().to_string();
        assert!(e.contains("16385 x 1 pixels"), "{e}");
        let e = load_one("bad.png", &garbage).unwrap_err().to_string();
        assert!(e.contains("bad.png: is not a readable png image: "), "{e}");
    }

    #[test]
    fn only_png_and_jpeg_are_recognized() {
        assert_eq!(mime_of(b"\x89PNG\r\n\x1a\n...."), Some("image/png"));
        assert_eq!(mime_of(&[0xff, 0xd8, 0xff, 0xe0]), Some("image/jpeg"));
        assert_eq!(mime_of(b"GIF89a"), None);
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let gif = dir.join("t.gif");
        std::fs::write(&gif, b"GIF89a").unwrap();
        let e = load(&[Some(gif.to_string_lossy().into_owned())], &Budget::default()).unwrap_err().to_string();
        assert!(e.contains("t.gif") && e.contains("not a PNG or JPEG"), "{e}");
    }
}
