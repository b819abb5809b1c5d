use super::*;

#[test]
fn writes_the_scene_and_its_sky_map() {
    let dir = tempfile::tempdir().unwrap();
    let o = CourtyardOptions::default();
    let s = generate(&o, dir.path(), &mut |_| {}).unwrap();
    let text = std::fs::read_to_string(&s.scene_path).unwrap();
    assert!(text.contains("LightSource \"infinite\" \"string mapname\" \"sky.pfm\""));
    assert_eq!(text.matches("Shape \"trianglemesh\"").count(), 9);
    assert_eq!(s.unique_triangles, 18);
    let sky = std::fs::read(dir.path().join("sky.pfm")).unwrap();
    let header = format!("PF\n{} {}\n-1.0\n", o.sky_width, o.sky_width / 2);
    assert!(sky.starts_with(header.as_bytes()));
    assert_eq!(
        sky.len(),
        header.len() + 12 * (o.sky_width * (o.sky_width / 2)) as usize
    );
    // The zenith is brighter than the horizon, and below it the ground is dark.
    let [z, h, g] = [0.05, 1.5, 2.5].map(|t| sky_radiance(t, 0.0)[1]);
    assert!(z > h && h > g, "{z} {h} {g}");
    assert!(generate(
        &CourtyardOptions {
            width: 0,
            ..o.clone()
        },
        dir.path(),
        &mut |_| {}
    )
    .is_err());
}
