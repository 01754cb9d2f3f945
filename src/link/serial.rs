//! Serial devices (telemetry radios, USB autopilots), read as a byte stream through our own
//! framer like TCP, so that bad CRCs, resyncs and unknown ids on a radio link are counted too.

use super::conn::Read;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

pub(super) struct Serial(Box<tokio_serial::SerialStream>);

impl Serial {
    pub(super) fn open(device: &str, baud: u32) -> std::io::Result<Self> {
        use tokio_serial::SerialPortBuilderExt;
        let port = tokio_serial::new(device, baud)
            .open_native_async()
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(Self(Box::new(port)))
    }

    pub(super) async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<Read> {
        match self.0.read(buf).await? {
            0 => {
                // A closed device (USB radio unplugged): wait and let the caller's link-loss
                // timer report it, rather than spinning.
                tokio::time::sleep(Duration::from_millis(100)).await;
                Ok(Read::Nothing)
            }
            n => Ok(Read::Bytes(n)),
        }
    }

    pub(super) async fn send(&mut self, frame: &[u8]) -> std::io::Result<bool> {
        self.0.write_all(frame).await?;
        Ok(true)
    }
}
