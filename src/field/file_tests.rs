//! Tests of the field file: round trips, old versions, refusals.

use super::*;

/// Eight unit cells around the origin, each moved a little, the first fixed.
fn field() -> Field<3> {
    let centers: Vec<Vect<3>> = (0..8)
        .map(|k| Vect::<3>::from_fn(|a, _| if k >> a & 1 == 1 { 0.5 } else { -0.5 }))
        .collect();
    let motions = centers
        .iter()
        .map(|c| Motion {
            rot: Mat::<3>::identity(),
            pos: c + Vect::<3>::new(0.0, 0.0, 0.1 * c.x),
        })
        .collect();
    let mut prescribed = super::super::Prescribed::default();
    prescribed.set(0, 8, Affine::identity());
    let lifted = Affine {
        linear: Mat::<3>::identity(),
        translation: Vect::<3>::new(0.0, 0.0, 0.25),
    };
    let top = super::super::Shape::Any(vec![
        super::super::Shape::Part(Box::new(crate::spec::Region::Box {
            min: Vect::<3>::new(1e6 - 1.0, 2e6 - 1.0, 0.75),
            max: Vect::<3>::new(1e6 + 1.0, 2e6 + 1.0, 2.0),
        })),
        super::super::Shape::Not(Box::new(super::super::Shape::Part(Box::new(
            crate::spec::Region::Sphere {
                center: Vect::<3>::new(1e6, 2e6, 0.0),
                radius: 3.0,
            },
        )))),
    ]);
    let k = prescribed.shaped(lifted, top);
    prescribed.put(7, 8, k);
    Field {
        origin: Vect::<3>::new(1e6, 2e6, 0.0),
        halves: vec![0.5; 8],
        centers,
        motions,
        prescribed,
        heights_kept: true,
        trend: crate::solve::trend::TrendMap {
            affine: Affine {
                linear: Mat::<3>::new(1.0001, 0.0002, 0.0, -0.0002, 1.0001, 0.0, 0.0, 0.0, 1.0),
                translation: Vect::<3>::new(0.5, -0.25, 0.0),
            },
            centers: vec![[0.0, 1.0], [2.0, -1.0]],
            weights: vec![
                Vect::<3>::new(0.1, 0.0, -0.1),
                Vect::<3>::new(-0.1, 0.0, 0.1),
            ],
            scale: 3.0,
        },
    }
}

#[test]
fn saves_and_loads_the_transfer_and_the_prescribed_maps() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.field");
    let f = field();
    SavedField::new(f.clone(), Transfer::BlendIdw, None)
        .save(&path)
        .unwrap();
    let back = SavedField::<3>::load(&path).unwrap();
    assert_eq!(back.transfer, Transfer::BlendIdw);
    assert_eq!(back.field, f);
    assert!(back.rbf.is_none());
}

/// A version-1 file (no transfer, no maps) still loads, as a field for the RBF.
#[test]
fn loads_version_1_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v2.field");
    let mut f = field();
    f.prescribed = Default::default();
    f.heights_kept = false;
    f.trend = Default::default();
    let rbf = Rbf::new(&f).unwrap();
    SavedField::new(f.clone(), Transfer::Rbf, Some(rbf))
        .save(&path)
        .unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
    let cells = 16 + 1 + 3 * 8 + 8 + 8 * (3 + 1 + 9 + 3) * 8;
    assert_eq!(bytes[cells..cells + 8], 0u64.to_le_bytes(), "no maps");
    bytes.drain(cells..cells + 8);
    bytes.remove(16);
    let shapes = bytes.split_off(bytes.len() - 4);
    assert_eq!(
        shapes,
        0u32.to_le_bytes(),
        "no regions' borders (version 6)"
    );
    assert_eq!(bytes.pop(), Some(0), "no CRS (version 5)");
    assert_eq!(bytes.pop(), Some(0), "no window section (version 3)");
    let v1 = dir.path().join("v1.field");
    std::fs::write(&v1, &bytes).unwrap();
    let back = SavedField::<3>::load(&v1).unwrap();
    assert_eq!(back.transfer, Transfer::Rbf);
    assert_eq!(back.field, f);
    assert!(back.rbf.is_some());
    bytes[8..12].copy_from_slice(&7u32.to_le_bytes());
    std::fs::write(&v1, &bytes).unwrap();
    let e = SavedField::<3>::load(&v1).err().unwrap().to_string();
    assert!(e.contains("version 7"), "{e}");
}

fn crs() -> Crs {
    Crs {
        name: Some("NAD83(HARN) / New Mexico Central (ftUS)".into()),
        epsg: Some(2903),
        vertical_epsg: None,
        from: "WKT",
        wkt: Some("PROJCS[\"NAD83(HARN) / New Mexico Central (ftUS)\",UNIT[\"US survey foot\",0.3048006096012192],AUTHORITY[\"EPSG\",\"2903\"]]".into()),
        unit: Some(crate::crs::Unit::UsSurveyFoot),
        vertical_unit: None,
        unit_from: "the WKT".into(),
    }
}

/// A field records the CRS it was solved in, or none; a PU field's window keeps it too.
#[test]
fn saves_and_loads_the_crs() {
    let dir = tempfile::tempdir().unwrap();
    for (k, crs) in [None, Some(crs())].into_iter().enumerate() {
        let path = dir.path().join(format!("{k}.field"));
        SavedField::new(field(), Transfer::Pu, None)
            .with_crs(crs.clone())
            .save(&path)
            .unwrap();
        let back = SavedField::<3>::load(&path).unwrap();
        assert_eq!((back.crs, back.field), (crs.clone(), field()));
        let window = SavedField::<3>::load_window(
            &path,
            (
                Vect::<3>::new(1e6, 2e6, 0.0),
                Vect::<3>::new(1e6 + 0.5, 2e6 + 0.5, 0.5),
            ),
        )
        .unwrap();
        assert_eq!(window.crs, crs);
        // A damaged CRS section is a format error naming the file.
        let mut bytes = std::fs::read(&path).unwrap();
        let end = bytes.len() - shapes_len(&field());
        if crs.is_some() {
            bytes.drain(end - 3..end);
        } else {
            bytes[end - 1] = 7;
        }
        std::fs::write(&path, &bytes).unwrap();
        let e = SavedField::<3>::load(&path).err().unwrap();
        assert!(
            matches!(&e, Error::Format { path: p, .. } if *p == path),
            "{e}"
        );
    }
}

/// The bytes of a field's last section, the regions' borders (version 6).
fn shapes_len(f: &Field<3>) -> usize {
    let mut out = Vec::new();
    for (_, shape) in &f.prescribed.shapes {
        shape.write(&mut out);
    }
    4 + 4 * f.prescribed.shapes.len() + out.len()
}

/// A version-4 file (no CRS section) still loads, as a field with no CRS recorded.
#[test]
fn loads_version_4_files_without_a_crs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v4.field");
    let mut f = field();
    f.prescribed.shapes.clear();
    let mut bytes = SavedField::new(f.clone(), Transfer::Blend, None)
        .to_bytes()
        .unwrap();
    bytes.truncate(bytes.len() - shapes_len(&f));
    assert_eq!(bytes.pop(), Some(0), "the CRS flag of a field without one");
    bytes[8..12].copy_from_slice(&4u32.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let back = SavedField::<3>::load(&path).unwrap();
    assert_eq!(
        (back.crs, back.field, back.transfer),
        (None, f, Transfer::Blend)
    );
    // A version-4 file with a CRS section has a byte too many.
    bytes.push(0);
    std::fs::write(&path, &bytes).unwrap();
    assert!(SavedField::<3>::load(&path).is_err());
}
