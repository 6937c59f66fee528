//! The page, built into the binary: nothing is fetched from the internet.

/// `/`
pub(crate) const INDEX_HTML: &str = include_str!("../assets/index.html");
/// `/app.js`
pub(crate) const APP_JS: &str = include_str!("../assets/app.js");
/// `/style.css`
pub(crate) const STYLE_CSS: &str = include_str!("../assets/style.css");
