//! Outgoing e-mail through lettre: SMTP when `smtp_url` is configured, else
//! a file outbox (`data_dir/outbox/<id>.eml`) that a developer — or a test —
//! reads. Bodies are plain text in the encoding lettre picks (lines with
//! long links come out quoted-printable, which a naive copy breaks), so the
//! outbox also prints each mail's links, decoded, on standard output.

use crate::config::Config;
use lettre::message::header::ContentType;
use lettre::message::{Body, SinglePart};
use lettre::{AsyncFileTransport, AsyncSmtpTransport, AsyncTransport, Message, Tokio1Executor};

/// Where mail goes.
#[derive(Clone)]
pub enum Mailer {
    /// `.eml` files in a directory.
    Outbox(AsyncFileTransport<Tokio1Executor>),
    /// An SMTP relay.
    Smtp(AsyncSmtpTransport<Tokio1Executor>),
}

/// Mail that could not be built or sent.
#[derive(Debug, thiserror::Error)]
#[error("mail: {0}")]
pub struct MailError(String);

impl Mailer {
    /// The transport `config` asks for (creating the outbox directory).
    pub fn from_config(config: &Config) -> Result<Mailer, MailError> {
        if config.smtp_url.0.is_empty() {
            let dir = config.outbox_dir();
            std::fs::create_dir_all(&dir).map_err(|e| MailError(format!("{}: {e}", dir.display())))?;
            Ok(Mailer::Outbox(AsyncFileTransport::new(dir)))
        } else {
            let smtp = AsyncSmtpTransport::<Tokio1Executor>::from_url(&config.smtp_url.0)
                .map_err(|e| MailError(format!("smtp_url: {e}")))?
                .build();
            Ok(Mailer::Smtp(smtp))
        }
    }

    /// Sends a plain-text message.
    pub async fn send(&self, from: &str, to: &str, subject: &str, body: String) -> Result<(), MailError> {
        let message = Message::builder()
            .from(from.parse().map_err(|e| MailError(format!("sender {from:?}: {e}")))?)
            .to(to.parse().map_err(|e| MailError(format!("recipient {to:?}: {e}")))?)
            .subject(subject)
            .singlepart(SinglePart::builder().header(ContentType::TEXT_PLAIN).body(Body::new(body.clone())))
            .map_err(|e| MailError(e.to_string()))?;
        match self {
            Mailer::Outbox(t) => {
                let id = t.send(message).await.map_err(|e| MailError(e.to_string()))?;
                // Printed, not logged: the one place a local user reads them.
                println!("mail to {to} ({subject:?}) in the outbox as {id}.eml");
                for link in body.split_whitespace().filter(|w| w.starts_with("http://") || w.starts_with("https://")) {
                    println!("    link: {link}");
                }
                Ok(())
            }
            Mailer::Smtp(t) => t.send(message).await.map(drop).map_err(|e| MailError(e.to_string())),
        }
    }
}
