//! What the service serves from inside the binary: the upload page (`web/`)
//! and the bundled sample scenes (`scenes/`, listed by `build.rs`).

/// A file of the upload page.
pub struct Asset {
    pub path: &'static str,
    pub content_type: &'static str,
    pub body: &'static str,
}

/// One of the page's ES modules (`web/*.js`), served at `/NAME`.
macro_rules! script {
    ($name:literal) => {
        Asset {
            path: concat!("/", $name),
            content_type: "text/javascript; charset=utf-8",
            body: include_str!(concat!("../../web/", $name)),
        }
    };
}

pub const PAGE: [Asset; 12] = [
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
    script!("app.js"),
    script!("binary.js"),
    script!("decode.js"),
    script!("editor.js"),
    script!("format.js"),
    script!("framebuffer.js"),
    script!("limits.js"),
    script!("request.js"),
    script!("scene-info.js"),
    script!("tiles.js"),
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
    use crate::limits;

    /// The value of `export const NAME = …;` in the page's `limits.js`.
    fn page_constant(name: &str) -> u64 {
        let limits_js = page_asset("/limits.js").unwrap().body;
        let prefix = format!("export const {name} = ");
        let line = limits_js
            .lines()
            .find_map(|l| l.strip_prefix(&prefix))
            .unwrap_or_else(|| panic!("web/limits.js has no {name}"));
        let expr = line.trim_end_matches(';');
        expr.split('*')
            .map(|f| {
                f.trim()
                    .parse::<u64>()
                    .unwrap_or_else(|_| panic!("{name} = {expr}"))
            })
            .product()
    }

    #[test]
    fn the_page_knows_the_servers_limits_and_defaults() {
        assert_eq!(page_constant("MAX_SPP"), u64::from(limits::MAX_SPP));
        assert_eq!(page_constant("MAX_DEPTH"), u64::from(limits::MAX_DEPTH));
        assert_eq!(
            page_constant("DEFAULT_CLASSIC_DEPTH"),
            u64::from(limits::DEFAULT_CLASSIC_DEPTH)
        );
        assert_eq!(
            page_constant("DEFAULT_BROWSER_DEPTH"),
            u64::from(limits::DEFAULT_BROWSER_DEPTH)
        );
        let default_spp = crate::render::RenderOptions::default().spp;
        assert_eq!(page_constant("DEFAULT_SPP"), u64::from(default_spp));
        assert_eq!(
            page_constant("BINARY_SNIFF_BYTES"),
            limits::BINARY_SNIFF_BYTES as u64
        );
    }

    #[test]
    fn every_module_the_page_imports_is_served() {
        for asset in PAGE.iter().filter(|a| a.path.ends_with(".js")) {
            for line in asset.body.lines() {
                let Some((_, from)) = line.split_once(" from './") else {
                    continue;
                };
                let module = from.trim_end_matches(['\'', ';']);
                assert!(
                    page_asset(&format!("/{module}")).is_some(),
                    "{} imports ./{module}, which is not served",
                    asset.path
                );
            }
        }
        let html = page_asset("/").unwrap().body;
        assert!(html.contains(r#"<script type="module" src="/app.js">"#));
    }

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
