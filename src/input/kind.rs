//! What an input file is, from its first bytes (issue 51, item 7): the
//! readers are chosen by content, and a file cdvol cannot read is named
//! for what it is ("PNG image") instead of failing as a sidecar that is
//! not UTF-8. The name decides only where the content does not: a gzip
//! stream is NIfTI when named `.nii.gz`, and a file named `.nrrd`,
//! `.nhdr` or `.nii` that starts like nothing known goes to that reader,
//! which names what is wrong with it.

use std::io::Read;
use std::path::Path;

/// The kinds of input file [`sniff`] tells apart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Kind {
    /// An NRRD header (`NRRD000n`), attached or detached.
    Nrrd,
    /// NIfTI-1 single file (`n+1` at byte 344), or gzip named `.nii.gz`.
    Nifti,
    /// A JSON document: a raw stack's sidecar.
    Sidecar,
    /// A TIFF (classic or BigTIFF): a multi-page stack.
    Tiff,
    /// A cdvol packed file (already prepared).
    Packed,
    /// Something cdvol does not read, in words ("PNG image").
    Unsupported(&'static str),
}

impl Kind {
    /// The kind in words, for `info`.
    pub fn name(&self) -> &'static str {
        match self {
            Kind::Nrrd => "NRRD",
            Kind::Nifti => "NIfTI-1",
            Kind::Sidecar => "raw stack (JSON sidecar)",
            Kind::Tiff => "TIFF stack",
            Kind::Packed => "cdvol packed file",
            Kind::Unsupported(what) => what,
        }
    }
}

/// What cdvol reads, for messages about what it does not.
pub const READS: &str = "cdvol reads DICOM series (give the directory), TIFF stacks (a directory \
                         of one TIFF per slice, or a multi-page TIFF), NIfTI (.nii, .nii.gz), \
                         NRRD (.nrrd, .nhdr) and raw stacks described by a JSON sidecar";

/// The kind of the regular file `path` from its first 512 bytes and,
/// for gzip, its name.
pub fn sniff(path: &Path) -> std::io::Result<Kind> {
    let mut head = Vec::with_capacity(512);
    crate::fsutil::open_regular(path)?
        .take(512)
        .read_to_end(&mut head)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    Ok(kind_of(&head, &name))
}

/// [`sniff`] of the bytes `head` of a file named `name` (lower case).
pub fn kind_of(head: &[u8], name: &str) -> Kind {
    let starts = |m: &[u8]| head.starts_with(m);
    if starts(b"NRRD000") {
        return Kind::Nrrd;
    }
    if head.get(344..348).is_some_and(|m| m == b"n+1\0") {
        return Kind::Nifti;
    }
    if head.get(344..348).is_some_and(|m| m == b"ni1\0") {
        return Kind::Unsupported(
            "NIfTI header of a .hdr/.img pair (cdvol reads the single-file .nii)",
        );
    }
    if head.get(4..8).is_some_and(|m| m == b"n+2\0") {
        return Kind::Unsupported("NIfTI-2 file (cdvol reads NIfTI-1)");
    }
    if starts(&[0x1f, 0x8b]) {
        return if name.ends_with(".nii.gz") {
            Kind::Nifti
        } else {
            Kind::Unsupported(
                "gzip-compressed data (cdvol reads gzip only as .nii.gz or inside NRRD)",
            )
        };
    }
    if head.get(128..132).is_some_and(|m| m == b"DICM") {
        return Kind::Unsupported("a single DICOM file (give the directory of its series)");
    }
    if starts(b"CDVOLPK") {
        return Kind::Packed;
    }
    if starts(b"II*\0") || starts(b"MM\0*") || starts(b"II+\0") || starts(b"MM\0+") {
        return Kind::Tiff;
    }
    let unsupported = [
        (&b"\x89PNG"[..], "PNG image"),
        (&b"\xff\xd8\xff"[..], "JPEG image"),
        (&b"GIF8"[..], "GIF image"),
        (&b"BM"[..], "BMP image"),
        (&b"PK\x03\x04"[..], "ZIP archive"),
        (&b"\x89HDF"[..], "HDF5 file"),
        (&b"%PDF"[..], "PDF document"),
        (&b"RIFF"[..], "RIFF file (WebP, WAV or AVI)"),
    ];
    if let Some((_, what)) = unsupported.iter().find(|(m, _)| starts(m)) {
        return Kind::Unsupported(what);
    }
    // Named as a format but not starting like one: its reader names what
    // is wrong (a bad magic line, a short header).
    if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        return Kind::Nrrd;
    }
    if name.ends_with(".nii") {
        return Kind::Nifti;
    }
    let text = head.iter().find(|b| !b.is_ascii_whitespace());
    if text == Some(&b'{') || name.ends_with(".json") {
        return Kind::Sidecar;
    }
    if head.is_empty() {
        return Kind::Unsupported("an empty file");
    }
    Kind::Unsupported(
        "raw binary data or an unknown format (a raw stack needs a JSON sidecar that names it, \
         docs/FORMAT.md)",
    )
}
