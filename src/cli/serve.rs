//! `bitrock serve WATCH_DIR`: the live page of a watch directory, read-only, following the
//! windows a running watch stores until Ctrl-C.

use super::print;
use super::watch::{STOP, start_server, stop_on_ctrl_c};
use bitrock::watch::serve::{DEFAULT_ADDRESS, page_meta};
use bitrock::watch::store::Reader;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;

/// How often the watch directory is read for new windows.
const POLL: std::time::Duration = std::time::Duration::from_millis(250);

#[derive(Debug, Args)]
pub struct ServeCmd {
    /// The watch directory (`bitrock watch --out DIR`).
    pub dir: PathBuf,
    /// Where to serve the page (HOST:PORT; this machine only by default; 0.0.0.0:PORT serves
    /// the network).
    #[arg(long, value_name = "ADDR", default_value = DEFAULT_ADDRESS)]
    pub address: String,
}

pub fn run(cmd: &ServeCmd) -> anyhow::Result<ExitCode> {
    let reader = Reader::open(&cmd.dir)?;
    let server = start_server(&cmd.address, "address", &cmd.dir)?;
    server.set_meta(&page_meta(&reader.meta));
    stop_on_ctrl_c("stopping the server");
    let mut last = None;
    while !STOP.load(Ordering::SeqCst) {
        let updates = reader.updates_after(last)?;
        if let Some(newest) = updates.last() {
            let view = reader.view()?.filter(|v| v.window == newest.window);
            for (k, update) in updates.iter().enumerate() {
                let newest = k + 1 == updates.len();
                server.publish(update, view.as_ref().filter(|_| newest));
            }
            last = Some(newest.window);
        } else if !server.is_ended() {
            // The page says how the watch ended: as it recorded, or killed where no watch
            // writes the directory and none recorded its end.
            if let Some(ended) = reader.ended()? {
                server.mark_ended(&ended);
            } else if !reader.is_written() {
                server.mark_ended(&serde_json::json!({
                    "said": "the watch is not running and recorded no end (killed?): its windows so far"
                }));
            }
        }
        std::thread::sleep(POLL);
    }
    server.end(&serde_json::json!({ "said": "the server was stopped" }));
    print::note(format_args!("note: the server of {} stopped", cmd.dir.display()));
    Ok(ExitCode::SUCCESS)
}
