//! The build ID of an executable: the linker's hash of the linked file, kept in an ELF note
//! (`NT_GNU_BUILD_ID`, what `readelf -n` prints). It names one build for the cost of reading
//! the headers, where hashing the file itself reads all of it (80 MB for a release blendsim,
//! about 60 ms of every `bake --from`).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// `PT_NOTE`: a program header of notes.
const PT_NOTE: u32 = 4;
/// `NT_GNU_BUILD_ID`: the note type of the build ID.
const NT_GNU_BUILD_ID: u32 = 3;
/// Notes segments larger than this are not read (a build ID's segment is a few dozen bytes).
const MAX_NOTES: u64 = 1 << 16;

/// The GNU build ID of the 64-bit little-endian ELF file at `path`; `None` for any other file,
/// one without the note, or one that cannot be read.
pub fn gnu_build_id(path: &Path) -> Option<Vec<u8>> {
    let mut file = File::open(path).ok()?;
    let mut header = [0u8; 64];
    file.read_exact(&mut header).ok()?;
    // The magic, 64-bit class, little-endian data.
    if header[..4] != *b"\x7fELF" || header[4] != 2 || header[5] != 1 {
        return None;
    }
    let u16_at = |b: &[u8], i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    let (phoff, phentsize, phnum) = (u64_at(&header, 0x20)?, u16_at(&header, 0x36) as usize, u16_at(&header, 0x38) as usize);
    if phentsize < 56 {
        return None;
    }
    let mut headers = vec![0u8; phentsize * phnum];
    file.seek(SeekFrom::Start(phoff)).ok()?;
    file.read_exact(&mut headers).ok()?;
    for ph in headers.chunks_exact(phentsize) {
        let (kind, offset, size) = (u32_at(ph, 0)?, u64_at(ph, 8)?, u64_at(ph, 32)?);
        if kind != PT_NOTE || size > MAX_NOTES {
            continue;
        }
        let mut notes = vec![0u8; size as usize];
        file.seek(SeekFrom::Start(offset)).ok()?;
        file.read_exact(&mut notes).ok()?;
        if let Some(id) = build_id_note(&notes) {
            return Some(id);
        }
    }
    None
}

/// The build ID among the notes of one segment: each note is its name's and description's
/// sizes, its type, then the name and the description, each padded to 4 bytes.
fn build_id_note(mut notes: &[u8]) -> Option<Vec<u8>> {
    let padded = |n: usize| n.div_ceil(4) * 4;
    while notes.len() >= 12 {
        let (name_size, desc_size, kind) = (u32_at(notes, 0)? as usize, u32_at(notes, 4)? as usize, u32_at(notes, 8)?);
        let name = notes.get(12..12 + name_size)?;
        let desc_start = 12 + padded(name_size);
        let desc = notes.get(desc_start..desc_start + desc_size)?;
        if kind == NT_GNU_BUILD_ID && name == b"GNU\0" && !desc.is_empty() {
            return Some(desc.to_vec());
        }
        notes = notes.get(desc_start + padded(desc_size)..)?;
    }
    None
}

fn u32_at(b: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(i..i + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], i: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal ELF64 file: the header, one program header, then its segment of `notes`.
    fn elf_with_notes(kind: u32, notes: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 64];
        b[..4].copy_from_slice(b"\x7fELF");
        (b[4], b[5]) = (2, 1);
        b[0x20..0x28].copy_from_slice(&64u64.to_le_bytes());
        b[0x36..0x38].copy_from_slice(&56u16.to_le_bytes());
        b[0x38..0x3a].copy_from_slice(&1u16.to_le_bytes());
        let mut ph = vec![0u8; 56];
        ph[..4].copy_from_slice(&kind.to_le_bytes());
        ph[8..16].copy_from_slice(&120u64.to_le_bytes());
        ph[32..40].copy_from_slice(&(notes.len() as u64).to_le_bytes());
        b.extend(ph);
        b.extend(notes);
        b
    }

    fn note(name: &[u8], kind: u32, desc: &[u8]) -> Vec<u8> {
        let mut n = Vec::new();
        for v in [name.len() as u32, desc.len() as u32, kind] {
            n.extend(v.to_le_bytes());
        }
        n.extend(name);
        n.resize(n.len().div_ceil(4) * 4, 0);
        n.extend(desc);
        n.resize(n.len().div_ceil(4) * 4, 0);
        n
    }

    #[test]
    fn the_build_id_is_read_from_the_note_segment_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("blendsim-build-id-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let read = |bytes: &[u8]| {
            let path = dir.join("file");
            std::fs::write(&path, bytes).unwrap();
            gnu_build_id(&path)
        };
        let id: Vec<u8> = (1..=20).collect();
        // Another note before it (an ABI tag, name padded), then the build ID.
        let notes = [note(b"GNU\0", 1, &[0, 0, 0, 0, 3, 0, 0, 0]), note(b"GNU\0", NT_GNU_BUILD_ID, &id)].concat();
        assert_eq!(read(&elf_with_notes(PT_NOTE, &notes)), Some(id.clone()));
        // Not a note segment, another owner's note, a truncated note, not an ELF file: none.
        assert_eq!(read(&elf_with_notes(1, &notes)), None);
        assert_eq!(read(&elf_with_notes(PT_NOTE, &note(b"Xen\0", NT_GNU_BUILD_ID, &id))), None);
        assert_eq!(read(&elf_with_notes(PT_NOTE, &notes[..notes.len() - 8])), None);
        assert_eq!(read(b"#!/bin/sh\n"), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn the_running_executable_has_the_id_readelf_prints() {
        let exe = std::env::current_exe().unwrap();
        let Some(id) = gnu_build_id(&exe) else { panic!("{} has no build ID", exe.display()) };
        let hex: String = id.iter().map(|b| format!("{b:02x}")).collect();
        let Ok(out) = std::process::Command::new("readelf").arg("-n").arg(&exe).output() else {
            panic!("readelf (binutils) is needed to check the build ID");
        };
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains(&format!("Build ID: {hex}")), "readelf -n says:\n{text}");
    }
}
