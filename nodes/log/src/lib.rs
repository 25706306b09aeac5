//! Player's logs: the `writelog` and `readlog` drivers and the text
//! format they share.

pub mod readlog;
pub mod text;
pub mod writelog;

pub use readlog::ReadLog;
pub use writelog::WriteLog;
