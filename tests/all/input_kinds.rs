//! Inputs by content (issue 51, item 7): a file cdvol does not read is
//! named for what it is, with what cdvol reads; readers are chosen by
//! content, not by name; and `cdvol info` describes an input before prep.
//! Before, `prep picture.png` and `prep cranium.raw` said "cannot read
//! sidecar: invalid utf-8 sequence", and `info` refused a NIfTI with "not
//! a cdvol packed file (magic [1f, 8b...])".

use crate::common::{cdvol, fails, ok, write_stack};

#[test]
fn unsupported_files_are_named_for_what_they_are() {
    let d = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| std::fs::write(d.path().join(name), bytes).unwrap();
    write("picture.png", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR");
    write("photo.jpg", b"\xff\xd8\xff\xe0\0\x10JFIF");
    write("cranium.raw", &[7u8; 4096]);
    write("anim.gif", b"GIF89a\x01\0\x01\0");
    write("data.gz", &[0x1f, 0x8b, 8, 0, 0, 0, 0, 0]);
    write("empty.json", b"");
    let mut dcm = vec![0u8; 132];
    dcm[128..132].copy_from_slice(b"DICM");
    write("slice.dcm", &dcm);
    for (name, what) in [
        ("picture.png", "PNG image"),
        ("photo.jpg", "JPEG image"),
        ("cranium.raw", "raw binary data"),
        ("anim.gif", "GIF image"),
        ("data.gz", "gzip-compressed data"),
        (
            "slice.dcm",
            "a single DICOM file (give the directory of its series)",
        ),
    ] {
        let e = fails(
            cdvol()
                .current_dir(d.path())
                .args(["prep", name, "-o", "out.cdv", "--iso", "1"]),
        );
        for w in [
            name,
            what,
            "cdvol reads DICOM series",
            "NIfTI",
            "NRRD",
            "sidecar",
        ] {
            assert!(e.contains(w), "{name}: {w:?} not in {e}");
        }
        assert!(!e.contains("utf-8"), "{e}");
    }
    // A TIFF goes to the TIFF reader, which names the file and what is
    // wrong with it (here: an image directory that ends after its header).
    write("broken.tif", b"II*\0\x08\0\0\0");
    let e = fails(cdvol().current_dir(d.path()).args([
        "prep",
        "broken.tif",
        "-o",
        "out.cdv",
        "--iso",
        "1",
    ]));
    assert!(e.contains("broken.tif") && e.contains("TIFF"), "{e}");
    // A packed file given to prep.
    let v: Vec<f64> = (0..4 * 4 * 3).map(|i| (i * 7 % 50) as f64).collect();
    write_stack(d.path(), "v", [4, 4, 3], "u8", &v, ["1", "1", "1"], "");
    ok(cdvol()
        .current_dir(d.path())
        .args(["prep", "-q", "v.json", "-o", "v.cdv", "--iso", "10"]));
    let e = fails(
        cdvol()
            .current_dir(d.path())
            .args(["prep", "v.cdv", "-o", "w.cdv", "--iso", "1"]),
    );
    assert!(e.contains("a cdvol packed file, already prepared"), "{e}");
}

#[test]
fn readers_are_chosen_by_content_and_info_describes_inputs() {
    let d = tempfile::tempdir().unwrap();
    let v: Vec<f64> = (0..4 * 4 * 3).map(|i| (i * 7 % 50) as f64).collect();
    write_stack(d.path(), "v", [4, 4, 3], "u8", &v, ["1", "1", "2"], "");
    // A sidecar and an NRRD under names that say nothing.
    std::fs::copy(d.path().join("v.json"), d.path().join("v.sidecar")).unwrap();
    let mut nrrd = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 3\nencoding: raw\n\
                     spacings: 1 1 2\n\n"
        .to_vec();
    nrrd.extend(v.iter().map(|&x| x as u8));
    std::fs::write(d.path().join("scan.data"), &nrrd).unwrap();
    for name in ["v.sidecar", "scan.data", "v.json"] {
        let text = ok(cdvol().current_dir(d.path()).args(["info", name]));
        for w in [
            "not prepared",
            "dims         4 x 4 x 3 samples",
            "values       0 .. 49 (rescaled)",
            "spacing z    2.0000 .. 2.0000 mm",
            "orientation  unknown",
            "cdvol prep",
        ] {
            assert!(text.contains(w), "{name}: {w:?} not in {text}");
        }
        let json: serde_json::Value = serde_json::from_str(&ok(cdvol()
            .current_dir(d.path())
            .args(["info", "--json", name])))
        .unwrap();
        assert_eq!(
            json["value_range"],
            serde_json::json!([0.0, 49.0]),
            "{json}"
        );
        ok(cdvol()
            .current_dir(d.path())
            .args(["prep", "-q", name, "-o", "p.cdv", "--iso", "10"]));
    }
    let text = ok(cdvol().current_dir(d.path()).args(["info", "scan.data"]));
    assert!(text.contains("(NRRD, not prepared)"), "{text}");
}
