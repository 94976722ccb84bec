//! `.mymaterial` parsing: the OpenDDL grammar, material semantics, and (data-driven) the error
//! message of every malformed file in `tests/fixtures/material_errors`.

use std::path::Path;

use cirrus::kinds::material::definition::parse_material_file;
use cirrus::openddl::{self, StructureBody, Value};
use cirrus::texture::TextureSlot;
use expect_test::expect;

#[test]
fn openddl_grammar_covers_names_properties_literals_comments_and_crlf() {
    let text = "// comment\r\nMetric (key = \"distance\", flag) {float {1.5, -2e3, 0x3F800000}}\r\n\
                Node $root { /* block\r\n comment */ Node %child (n = 0b101) { int32[2] {{1, 'A'}, {-0o17, +3}} }\r\n\
                string { \"a\\tb\" \"\\u00e9\\x21\" } ref {$root%child, null} type {float} bool {true, false} } ";
    let structures = openddl::parse(text).expect("valid OpenDDL");
    assert_eq!(structures.len(), 2);
    let StructureBody::Custom { identifier, properties, children } = &structures[0].body else { panic!("custom") };
    assert_eq!(identifier, "Metric");
    assert_eq!(properties[0].value, Value::String("distance".into()));
    assert_eq!(properties[1].value, Value::Bool(true), "a property without a value is true");
    let StructureBody::Primitive { values, .. } = &children[0].body else { panic!("primitive") };
    assert_eq!(
        values,
        &[Value::Float(1.5), Value::Float(-2000.0), Value::Float(1.0)],
        "hex float literal is a bit pattern"
    );
    let node = &structures[1];
    assert_eq!(node.name.as_ref().map(|name| name.to_string()), Some("$root".to_string()));
    assert_eq!(node.position.line, 3, "CRLF line endings count once");
    let child = &node.children()[0];
    assert_eq!(child.name.as_ref().map(|name| name.to_string()), Some("%child".to_string()));
    assert_eq!(child.property("n").map(|p| p.value.clone()), Some(Value::Integer(5)));
    let StructureBody::Primitive { array_size, values, .. } = &child.children()[0].body else { panic!("array") };
    assert_eq!(*array_size, Some(2));
    assert_eq!(values, &[Value::Integer(1), Value::Integer(65), Value::Integer(-15), Value::Integer(3)]);
    let StructureBody::Primitive { values, .. } = &node.children()[1].body else { panic!("string") };
    assert_eq!(values, &[Value::String("a\tbé!".into())], "escapes and concatenation");
    assert_eq!(node.children().len(), 5);
}

#[test]
fn material_file_with_two_materials_resolves_paths_and_constants() {
    let text = br#"
        Material $oak { Name {string {"Oak"}}
            Texture (attrib = "diffuse") {string {"..\\textures\\oak albedo.png"}}
            Texture (attrib = "ao") { string {"../textures/ao.png"} }
            Param (attrib = "metallic") {float {0.25}}
            Color (attrib = "specular") {float[3] {{0.5, 0.5, 0.5}}}
            Transform {float[16] {{1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1}}}
        }
        Material %birch { Color (attrib = "diffuse") {float[3] {{0.2, 0.4, 0.6}}} }
        Light $sun {}
    "#;
    let parsed =
        parse_material_file(Path::new("assets/materials/trees.mymaterial"), text, Path::new("assets")).expect("valid");
    let names: Vec<&str> = parsed.materials.iter().map(|material| material.name.as_str()).collect();
    assert_eq!(names, ["oak", "birch"]);
    let oak = &parsed.materials[0];
    assert_eq!(oak.textures[&TextureSlot::Albedo].path, Path::new("assets/textures/oak albedo.png"));
    assert_eq!(oak.textures[&TextureSlot::Ao].position.line, 4);
    assert_eq!(oak.constants.metallic, 0.25);
    assert_eq!(oak.constants.roughness, 1.0, "default roughness");
    assert_eq!(parsed.materials[1].constants.albedo, [0.2, 0.4, 0.6, 1.0]);
    let warnings: Vec<String> = parsed.warnings.iter().map(ToString::to_string).collect();
    expect![[r#"
        [
            "assets/materials/trees.mymaterial:6:13: color attrib \"specular\" is not used by the PBR baker",
            "assets/materials/trees.mymaterial:7:13: `Transform` structure ignored inside `Material`",
            "assets/materials/trees.mymaterial:10:9: `Light` structure ignored: only `Material` is read at the top level",
        ]
    "#]]
    .assert_debug_eq(&warnings);
}

/// Every `tests/fixtures/material_errors/*.mymaterial` fails with the message in its `.expected`
/// file (run with `UPDATE_EXPECT=1` to rewrite them).
#[test]
fn malformed_material_files_report_file_line_and_column() {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/material_errors");
    let mut files: Vec<_> =
        std::fs::read_dir(&folder).expect("fixture folder").flatten().map(|entry| entry.path()).collect();
    files.retain(|path| path.extension().is_some_and(|extension| extension == "mymaterial"));
    files.sort();
    assert!(files.len() >= 8, "fixtures present");
    for path in files {
        let bytes = std::fs::read(&path).expect("fixture");
        let name = Path::new("materials").join(path.file_name().expect("file name"));
        let error = parse_material_file(&name, &bytes, Path::new("")).expect_err("the fixture is malformed");
        let expected = path.with_extension("expected");
        expect_test::expect_file![expected].assert_eq(&format!("{error}\n"));
    }
}
