//! What the service serves from inside the binary: the upload page (`web/`)
//! and the bundled sample scenes (`scenes/`, listed by `build.rs`).

/// A file of the upload page.
pub struct Asset {
    pub path: &'static str,
    pub content_type: &'static str,
    pub body: &'static str,
}

pub const PAGE: [Asset; 3] = [
    Asset {
        path: "/",
        content_type: "text/html; charset=utf-8",
        body: include_str!("../../web/index.html"),
    },
    Asset {
        path: "/style.css",
        content_type: "text/css; charset=utf-8",
        body: include_str!("../../web/style.css"),
    },
    Asset {
        path: "/app.js",
        content_type: "text/javascript; charset=utf-8",
        body: include_str!("../../web/app.js"),
    },
];

/// The bundled sample scenes: (file name, contents), sorted by name.
pub const SCENES: &[(&str, &[u8])] = include!(concat!(env!("OUT_DIR"), "/scenes.rs"));

pub fn page_asset(path: &str) -> Option<&'static Asset> {
    PAGE.iter().find(|a| a.path == path)
}

pub fn scene(name: &str) -> Option<&'static [u8]> {
    SCENES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// `[{"name":"testSample.txt","bytes":345}, …]`
pub fn scene_list_json() -> String {
    let entries: Vec<String> = SCENES
        .iter()
        .map(|(name, text)| {
            let name = serde_json::Value::from(*name);
            format!("{{\"name\":{name},\"bytes\":{}}}", text.len())
        })
        .collect();
    format!("[{}]", entries.join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bundled_scene_parses() {
        assert!(scene("testSample.txt").is_some());
        let list: serde_json::Value = serde_json::from_str(&scene_list_json()).unwrap();
        assert_eq!(list.as_array().unwrap().len(), SCENES.len());
        assert!(scene_list_json().contains(r#"{"name":"testSample.txt","bytes":337}"#));
        for (name, text) in SCENES {
            crate::scene::parse(text).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }
}
