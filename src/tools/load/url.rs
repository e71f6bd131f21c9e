//! The URL requests go to: `http://host[:port][/path][?query]`.

use super::UrlError;

/// Where requests go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Url {
    /// `host:port` as written, for the `Host` header.
    pub authority: String,
    /// Path and query, e.g. `/render?spp=2`.
    pub target: String,
}

impl Url {
    /// Parses `http://host[:port][/path][?query]`.
    pub fn parse(url: &str) -> Result<Url, UrlError> {
        let rest = url
            .strip_prefix("http://")
            .ok_or_else(|| UrlError::NotHttp(url.to_owned()))?;
        let (authority, target) = match rest.find(['/', '?']) {
            Some(i) => (&rest[..i], &rest[i..]),
            None => (rest, "/"),
        };
        if authority.is_empty() {
            return Err(UrlError::NoHost(url.to_owned()));
        }
        let authority = if authority
            .rsplit_once(':')
            .is_some_and(|(_, p)| p.bytes().all(|b| b.is_ascii_digit()))
            && !authority.ends_with(']')
        {
            authority.to_owned()
        } else {
            format!("{authority}:80")
        };
        let target = if target.starts_with('?') {
            format!("/{target}")
        } else {
            target.to_owned()
        };
        Ok(Url { authority, target })
    }

    /// What follows `?` in the target, without it; empty if none.
    pub(super) fn query(&self) -> &str {
        self.target.split_once('?').map_or("", |(_, query)| query)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_split_into_authority_and_target() {
        let u = Url::parse("http://127.0.0.1:8080/render?spp=2").unwrap();
        assert_eq!(
            (u.authority.as_str(), u.target.as_str()),
            ("127.0.0.1:8080", "/render?spp=2")
        );
        assert_eq!(u.query(), "spp=2");
        let u = Url::parse("http://localhost").unwrap();
        assert_eq!(
            (u.authority.as_str(), u.target.as_str()),
            ("localhost:80", "/")
        );
        assert_eq!(u.query(), "");
        assert_eq!(
            Url::parse("http://[::1]:9000/healthz").unwrap().authority,
            "[::1]:9000"
        );
        assert_eq!(
            Url::parse("https://x/"),
            Err(UrlError::NotHttp("https://x/".into()))
        );
        assert_eq!(
            Url::parse("http:///x"),
            Err(UrlError::NoHost("http:///x".into()))
        );
    }
}
