//! What stands between a hostile DICOM file and dicom-rs (issue 57).
//!
//! dicom-rs parses and decodes well-formed files, but three kinds of
//! malformed file took a whole `prep-batch` down with them:
//!
//! - **Nesting.** dicom-object builds a data set by recursion, one frame
//!   per sequence and item, so a file of 100,000 nested sequences
//!   overflowed the stack (SIGSEGV: no error, no batch.json).
//!   [`check_structure`] first walks the file with dicom-parser's lazy token
//!   reader, which keeps its open sequences in a `Vec`, skips values
//!   without reading them into memory and never recurses, and refuses
//!   nesting deeper than [`MAX_NESTING`] before dicom-object sees the file.
//! - **Lengths.** dicom-parser allocates an element's value by the length
//!   its header declares (`read_value_ob`), so nine bytes slipped in
//!   before PixelData made a 2.7 KB file ask for 276 MB (found by the
//!   fuzz target `fuzz_readers_dicom`). The same walk refuses a value whose
//!   declared length runs past the end of the file, and a binary value
//!   (US, UL, FD, ...) whose length is not a multiple of its size, which
//!   dicom-parser reads short and then misreads what follows ([`fixed_size`]).
//! - **Decoder panics.** The RLE Lossless decoder of
//!   dicom-transfer-syntax-registry 0.8 indexes the fragment by offsets
//!   read from it and unwraps a short read, so garbage pixel data panics
//!   (`rle_lossless.rs:230`); it also allocates `4 x` the header's segment
//!   count before checking it. [`check_rle`] checks the RLE header
//!   (PS3.5 G.3.1: at most 15 segments, offsets inside the fragment, in
//!   order) before the decoder runs, and [`no_panic`] turns any panic left
//!   inside dicom-rs into a named error for that file, without the panic
//!   message on stderr. The reproducer is the test
//!   `hostile_dicom::rle_garbage_is_a_named_error`; docs/RELIABILITY.md
//!   has the upstream note.
//! - **Sizes.** Rows x Columns x bytes is checked against the memory limit
//!   before anything of that size is allocated (module `super`).

use std::any::Any;
use std::cell::Cell;
use std::io::{BufReader, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

use dicom_core::VR;
use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, FileMetaTable};
use dicom_parser::dataset::lazy_read::LazyDataSetReader;
use dicom_parser::dataset::LazyDataToken;
use dicom_parser::StatefulDecode;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

use super::err;
use crate::input::InputError;

/// Deepest nesting of sequences a slice may have. Image slices nest a
/// few levels (a procedure code inside a request attribute sequence);
/// 32 sequences, each with an item, is far above that and far below what
/// dicom-object's recursion takes to fill a 2 MiB thread stack (the tests
/// parse a file nested this deep on such a thread).
pub const MAX_NESTING: usize = 32;

/// Refuses a file whose sequences nest deeper than [`MAX_NESTING`], or
/// one of whose values declares more bytes than the file has left,
/// before dicom-object parses it. With `until_pixel_data`, the walk stops
/// at the top-level PixelData (what a header read parses).
///
/// A file this walk cannot read is left to dicom-object, which reads it
/// with the same decoder and names the fault; only depth and lengths are
/// judged here.
pub fn check_structure(path: &Path, until_pixel_data: bool) -> Result<(), InputError> {
    let io = |source| InputError::Io {
        path: path.to_path_buf(),
        what: "cannot open",
        source,
    };
    let file = crate::fsutil::open_regular(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let past_end = |what: String, at: u64, len: u32| {
        err(
            path,
            "element length",
            format!(
                "{what} declares {len} bytes at byte {at}, past the end of the file \
                 ({file_len} bytes): a truncated or malformed file"
            ),
        )
    };
    let mut f = BufReader::new(file);
    check_meta(path, &mut f, file_len)?;
    if f.seek(SeekFrom::Start(128)).is_err() {
        return Ok(());
    }
    let Ok(meta) = FileMetaTable::from_reader(&mut f) else {
        return Ok(());
    };
    let uid = meta.transfer_syntax();
    let Some(ts) = TransferSyntaxRegistry.iter().find(|t| t.uid() == uid) else {
        return Ok(());
    };
    let Ok(mut rd) = LazyDataSetReader::new_with_ts(f, ts) else {
        return Ok(());
    };
    // Open sequences and items: one nesting level is a sequence and an
    // item inside it.
    let mut open = 0usize;
    while let Some(token) = rd.advance() {
        let Ok(token) = token else { return Ok(()) };
        let top = open == 0;
        match token {
            LazyDataToken::ElementHeader(h)
                if top && until_pixel_data && h.tag == tags::PIXEL_DATA =>
            {
                return Ok(())
            }
            LazyDataToken::PixelSequenceStart if top && until_pixel_data => return Ok(()),
            LazyDataToken::SequenceStart { .. }
            | LazyDataToken::PixelSequenceStart
            | LazyDataToken::ItemStart { .. } => open += 1,
            LazyDataToken::SequenceEnd | LazyDataToken::ItemEnd => open = open.saturating_sub(1),
            LazyDataToken::LazyValue { header, decoder } => {
                if let Some(len) = header.len.get() {
                    let at = decoder.position();
                    if let Some(size) = fixed_size(header.vr).filter(|&s| len % s != 0) {
                        return Err(err(
                            path,
                            "element length",
                            format!(
                                "element ({:04X},{:04X}) of VR {} declares {len} bytes at byte \
                                 {at}, expected a multiple of {size}: a malformed file",
                                header.tag.group(),
                                header.tag.element(),
                                header.vr.to_string()
                            ),
                        ));
                    }
                    if at.saturating_add(len as u64) > file_len {
                        let what = format!(
                            "element ({:04X},{:04X})",
                            header.tag.group(),
                            header.tag.element()
                        );
                        return Err(past_end(what, at, len));
                    }
                }
                let token = LazyDataToken::LazyValue { header, decoder };
                // A value that cannot be skipped: dicom-object names it.
                let Ok(()) = token.skip() else { return Ok(()) };
            }
            LazyDataToken::LazyItemValue { len, decoder } => {
                let at = decoder.position();
                if at.saturating_add(len as u64) > file_len {
                    return Err(past_end("an item".into(), at, len));
                }
                let token = LazyDataToken::LazyItemValue { len, decoder };
                let Ok(()) = token.skip() else { return Ok(()) };
            }
            _ => {}
        }
        if open > 2 * MAX_NESTING {
            return Err(err(
                path,
                "sequence nesting",
                format!(
                    "sequences nested more than {MAX_NESTING} deep, expected at most \
                     {MAX_NESTING} (a malformed or hostile file)"
                ),
            ));
        }
    }
    Ok(())
}

/// The size of one value of a VR whose values are binary numbers (or
/// tags), whose length must be a multiple of it (PS3.5 6.2). dicom-parser
/// reads `len / size` values of such an element but advances its position
/// by `len`, so a length of 2 for a UL put its reader 2 bytes behind the
/// element that follows: it then read text as a header and reserved the
/// 540 MB that text declared (fuzz target `fuzz_readers_dicom`).
fn fixed_size(vr: VR) -> Option<u32> {
    match vr {
        VR::US | VR::SS | VR::OW => Some(2),
        VR::UL | VR::SL | VR::FL | VR::OL | VR::OF | VR::AT => Some(4),
        VR::FD | VR::OD | VR::SV | VR::UV | VR::OV => Some(8),
        _ => None,
    }
}

/// Largest file meta group (group 0002) read: a few hundred bytes in
/// practice.
const MAX_META: u64 = 1 << 20;

/// Walks the file meta group (explicit VR little endian after the
/// 128-byte preamble and `DICM`) and refuses an element whose length runs
/// past the end of the file: dicom-object reserves each meta element's
/// declared length before reading it. It reads elements, of any group,
/// until it has read the bytes the group length (0002,0000) declares, so
/// this walk does too (a fuzzed file whose group length ran past group
/// 0002 into an element tagged (0002,0013) made it reserve 340 MB). A
/// file that does not start like DICOM is left to dicom-object.
fn check_meta(
    path: &Path,
    f: &mut BufReader<std::fs::File>,
    file_len: u64,
) -> Result<(), InputError> {
    use std::io::Read;
    let mut head = Vec::new();
    if f.seek(SeekFrom::Start(0)).is_err()
        || f.by_ref().take(MAX_META).read_to_end(&mut head).is_err()
        || head.len() < 132
        || &head[128..132] != b"DICM"
    {
        return Ok(());
    }
    // (0002,0000) UL of length 4: the group length dicom-object reads the
    // meta elements by; without it dicom-object refuses the file.
    let mut at = 132usize;
    if head.len() < at + 12 || head[at..at + 8] != [2, 0, 0, 0, b'U', b'L', 4, 0] {
        return Ok(());
    }
    let group_length =
        u32::from_le_bytes([head[at + 8], head[at + 9], head[at + 10], head[at + 11]]);
    at += 12;
    let stop = at as u64 + group_length as u64;
    while (at as u64) < stop && at + 8 <= head.len() {
        let vr = &head[at + 4..at + 6];
        // The VRs with a 2-byte length; dicom-rs reads any other (an
        // unknown one as UN) with 2 reserved bytes and a 4-byte length.
        let long = !matches!(
            vr,
            b"AE"
                | b"AS"
                | b"AT"
                | b"CS"
                | b"DA"
                | b"DS"
                | b"DT"
                | b"FL"
                | b"FD"
                | b"IS"
                | b"LO"
                | b"LT"
                | b"PN"
                | b"SH"
                | b"SL"
                | b"SS"
                | b"ST"
                | b"TM"
                | b"UI"
                | b"UL"
                | b"US"
        );
        let (len, value_at) = if long {
            if at + 12 > head.len() {
                break;
            }
            let mut b = [0u8; 4];
            b.copy_from_slice(&head[at + 8..at + 12]);
            (u32::from_le_bytes(b) as u64, at + 12)
        } else {
            (
                u16::from_le_bytes([head[at + 6], head[at + 7]]) as u64,
                at + 8,
            )
        };
        let end = value_at as u64 + len;
        if end > file_len || end > MAX_META {
            return Err(err(
                path,
                "file meta",
                format!(
                    "element ({:02X}{:02X},{:02X}{:02X}) declares {len} bytes at byte {value_at}, \
                     past the end of the file ({file_len} bytes) or of a {MAX_META}-byte meta group",
                    head[at + 1],
                    head[at],
                    head[at + 3],
                    head[at + 2]
                ),
            ));
        }
        at = end as usize;
    }
    Ok(())
}

/// The RLE Lossless transfer syntax.
const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// Checks the RLE header of frame 0 of an RLE Lossless file (PS3.5
/// G.3.1) before dicom-rs decodes it: a header of 64 bytes, 1 to 15
/// segments, as many as the samples have bytes, the first at byte 64 and
/// each inside the fragment, in order. Other transfer syntaxes pass.
pub fn check_rle(path: &Path, obj: &DefaultDicomObject, segments: usize) -> Result<(), InputError> {
    if obj.meta().transfer_syntax() != RLE_LOSSLESS {
        return Ok(());
    }
    let bad = |msg: String| err(path, "PixelData", format!("RLE Lossless: {msg}"));
    let px = obj
        .element(tags::PIXEL_DATA)
        .map_err(|_| err(path, "PixelData", "missing"))?;
    let Some(fragment) = px.fragments().and_then(|f| f.first()) else {
        return Err(bad("no fragment, expected one per frame".into()));
    };
    if fragment.len() < 64 {
        return Err(bad(format!(
            "a fragment of {} bytes, expected a 64-byte header and data",
            fragment.len()
        )));
    }
    let word = |i: usize| {
        let mut b = [0u8; 4];
        b.copy_from_slice(&fragment[4 * i..4 * i + 4]);
        u32::from_le_bytes(b) as usize
    };
    let n = word(0);
    if n != segments {
        return Err(bad(format!(
            "{n} segments in the header, expected {segments} (one per byte of a sample)"
        )));
    }
    let mut last = 64;
    for i in 0..n {
        let at = word(i + 1);
        if (i == 0 && at != 64) || at < last || at > fragment.len() {
            return Err(bad(format!(
                "segment {i} starts at byte {at}, expected {} within the fragment's {} bytes",
                if i == 0 {
                    "64".to_string()
                } else {
                    format!("at least {last}")
                },
                fragment.len()
            )));
        }
        last = at;
    }
    Ok(())
}

thread_local! {
    /// Set while this thread runs inside [`no_panic`]: its panics are
    /// caught and reported as errors, so the hook stays quiet.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

static HOOK: Once = Once::new();

/// Runs `f` (a call into dicom-rs on the file `path`) and turns a panic
/// inside it into an error naming the file and `field`. The panic hook
/// stays silent for panics caught here and prints the others as before.
pub fn no_panic<T>(
    path: &Path,
    field: &str,
    f: impl FnOnce() -> Result<T, InputError>,
) -> Result<T, InputError> {
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    r.unwrap_or_else(|payload| {
        Err(err(
            path,
            field,
            format!(
                "dicom-rs failed on this file ({}): the file is malformed",
                panic_text(payload.as_ref())
            ),
        ))
    })
}

fn panic_text(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic".into()
    }
}
