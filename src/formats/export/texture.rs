//! Diffuse textures of material groups (OBJ `map_Kd`) as the files carry them: embedded in a
//! glb, copied beside a USD file and referenced by a relative asset path.
//!
//! Only PNG and JPEG are carried: the two image formats glTF 2.0 core allows (USD's
//! UsdUVTexture reads them too). The format is told by the file's first bytes, not its name.

use std::path::Path;

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
pub fn mime_of(bytes: &[u8]) -> Option<&'static str> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some("image/png")
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        Some("image/jpeg")
    } else {
        None
    }
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

/// Read every group's texture (`None` for groups without one). Errors name the image file.
pub fn load(textures: &[Option<String>]) -> Result<Vec<Option<Texture>>> {
    let names = file_names(textures);
    textures
        .iter()
        .zip(names)
        .map(|(path, name)| {
            let (Some(path), Some(file_name)) = (path, name) else { return Ok(None) };
            let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e, "read the texture a material's map_Kd names"))?;
            let mime = mime_of(&bytes).ok_or_else(|| {
                Error::in_file(
                    path,
                    "is not a PNG or JPEG image (glTF carries only those)",
                    "convert it to PNG (or JPEG) and point the .mtl's map_Kd at the converted file",
                )
            })?;
            Ok(Some(Texture { file_name, bytes, mime }))
        })
        .collect()
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
    fn only_png_and_jpeg_are_recognized() {
        assert_eq!(mime_of(b"\x89PNG\r\n\x1a\n...."), Some("image/png"));
        assert_eq!(mime_of(&[0xff, 0xd8, 0xff, 0xe0]), Some("image/jpeg"));
        assert_eq!(mime_of(b"GIF89a"), None);
        let dir = std::env::temp_dir().join(format!("blendsim-texture-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let gif = dir.join("t.gif");
        std::fs::write(&gif, b"GIF89a").unwrap();
        let e = load(&[Some(gif.to_string_lossy().into_owned())]).unwrap_err().to_string();
        assert!(e.contains("t.gif") && e.contains("not a PNG or JPEG"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
