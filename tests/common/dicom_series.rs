//! A CT-like DICOM series written with dicom-rs, for tests/dicom.rs and
//! tests/batch.rs.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};

pub const NX: usize = 33;
pub const NY: usize = 28;
pub const SERIES: &str = "1.2.826.0.1.3680043.9.7777.1";
pub const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// Slice positions: 2 mm gaps low, 1 mm in the middle, 4 mm on top.
pub fn z_positions() -> Vec<f64> {
    let mut z = vec![-40.0];
    for i in 0..19 {
        let g = if i < 6 {
            2.0
        } else if i < 14 {
            1.0
        } else {
            4.0
        };
        z.push(z[i] + g);
    }
    z
}

/// Stored u16 values (HU + 1024) of slice `k`: a sphere and noise.
pub fn slice(k: usize) -> Vec<u16> {
    let z = z_positions()[k];
    let mut v = Vec::with_capacity(NX * NY);
    for y in 0..NY {
        for x in 0..NX {
            let (px, py, pz) = (x as f64 * 0.7 - 11.0, y as f64 * 0.8 - 11.0, z + 25.0);
            let r = (px * px + py * py + pz * pz).sqrt();
            let noise = ((x * 7 + y * 13 + k * 31) % 17) as f64;
            let hu = if r < 9.0 { 700.0 } else { -1000.0 } + noise;
            v.push((hu + 1024.0) as u16);
        }
    }
    v
}

pub struct Slice<'a> {
    pub k: usize,
    pub series: &'a str,
    pub rows: usize,
    pub position: [f64; 3],
    pub ts: &'a str,
}

pub fn write_slice(path: &Path, s: &Slice) {
    let ds = |v: &[f64]| PrimitiveValue::Strs(v.iter().map(|x| format!("{x}")).collect());
    let mut obj = InMemDicomObject::new_empty();
    let uid = format!("{}.{}.{}", s.series, s.k, s.rows);
    let put = |o: &mut InMemDicomObject, tag, vr, v: PrimitiveValue| {
        o.put(DataElement::new(tag, vr, v));
    };
    put(
        &mut obj,
        tags::SOP_CLASS_UID,
        VR::UI,
        "1.2.840.10008.5.1.4.1.1.2".into(),
    );
    put(
        &mut obj,
        tags::SOP_INSTANCE_UID,
        VR::UI,
        uid.as_str().into(),
    );
    put(&mut obj, tags::MODALITY, VR::CS, "CT".into());
    put(&mut obj, tags::SERIES_INSTANCE_UID, VR::UI, s.series.into());
    put(
        &mut obj,
        tags::INSTANCE_NUMBER,
        VR::IS,
        format!("{}", s.k + 1).as_str().into(),
    );
    put(
        &mut obj,
        tags::IMAGE_POSITION_PATIENT,
        VR::DS,
        ds(&s.position),
    );
    put(
        &mut obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        VR::DS,
        ds(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    );
    put(&mut obj, tags::PIXEL_SPACING, VR::DS, ds(&[0.8, 0.7]));
    put(
        &mut obj,
        tags::SAMPLES_PER_PIXEL,
        VR::US,
        PrimitiveValue::from(1u16),
    );
    put(
        &mut obj,
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        "MONOCHROME2".into(),
    );
    put(
        &mut obj,
        tags::ROWS,
        VR::US,
        PrimitiveValue::from(s.rows as u16),
    );
    put(
        &mut obj,
        tags::COLUMNS,
        VR::US,
        PrimitiveValue::from(NX as u16),
    );
    put(
        &mut obj,
        tags::BITS_ALLOCATED,
        VR::US,
        PrimitiveValue::from(16u16),
    );
    put(
        &mut obj,
        tags::BITS_STORED,
        VR::US,
        PrimitiveValue::from(16u16),
    );
    put(
        &mut obj,
        tags::HIGH_BIT,
        VR::US,
        PrimitiveValue::from(15u16),
    );
    put(
        &mut obj,
        tags::PIXEL_REPRESENTATION,
        VR::US,
        PrimitiveValue::from(0u16),
    );
    put(&mut obj, tags::RESCALE_INTERCEPT, VR::DS, ds(&[-1024.0]));
    put(&mut obj, tags::RESCALE_SLOPE, VR::DS, ds(&[1.0]));
    let mut px = slice(s.k);
    px.resize(NX * s.rows, 0);
    put(
        &mut obj,
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(px.into()),
    );
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(s.ts)
                .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.2")
                .media_storage_sop_instance_uid(uid.as_str()),
        )
        .unwrap();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    file.write_to_file(path).unwrap();
}

/// The series in `dir` under scrambled names, some nested; returns the
/// file of each slice.
pub fn write_series(dir: &Path) -> Vec<PathBuf> {
    (0..z_positions().len())
        .map(|k| {
            let name = format!("{:08x}", (k as u64 * 2654435761) % 4294967291);
            let p = if k % 3 == 0 {
                dir.join("sub").join(name)
            } else {
                dir.join(format!("{name}.dcm"))
            };
            write_slice(
                &p,
                &Slice {
                    k,
                    series: SERIES,
                    rows: NY,
                    position: [10.0, -5.0, z_positions()[k]],
                    ts: EXPLICIT_LE,
                },
            );
            p
        })
        .collect()
}
