//! Outgoing e-mail through lettre: SMTP when `smtp_url` is configured, else
//! a file outbox (`data_dir/outbox/<id>.eml`) that a developer — or a test —
//! reads. Bodies are plain text, sent as they are (7-bit) whenever they are
//! ASCII, so a link in an `.eml` file is whole and can be copied from it;
//! other bodies go in the encoding lettre picks (quoted-printable, whose
//! soft line breaks cut long links). The outbox also prints each mail's
//! links on standard output.

use crate::config::Config;
use lettre::message::header::{ContentTransferEncoding, ContentType};
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

/// `text` as a mail's one plain-text part (see [`plain_body`]).
fn plain_part(text: String) -> SinglePart {
    SinglePart::builder().header(ContentType::TEXT_PLAIN).body(plain_body(text))
}

/// `text` as a mail body: as it is (7-bit, CRLF line ends) when it can be
/// (ASCII without NUL or CR, lines of at most 998 characters, RFC 5322's
/// limit), else in lettre's choice of encoding. lettre itself would encode
/// any line of 76 characters or more, and every mail with a link has one.
fn plain_body(text: String) -> Body {
    let sendable_as_is =
        text.bytes().all(|b| b.is_ascii() && b != 0 && b != b'\r') && text.split('\n').all(|line| line.len() <= 998);
    if sendable_as_is {
        Body::dangerous_pre_encoded(text.replace('\n', "\r\n").into_bytes(), ContentTransferEncoding::SevenBit)
    } else {
        Body::new(text)
    }
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
            .singlepart(plain_part(body.clone()))
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

#[cfg(test)]
mod tests {
    use super::plain_part;

    fn formatted(text: &str) -> String {
        String::from_utf8(plain_part(text.to_string()).formatted()).unwrap()
    }

    #[test]
    fn a_long_link_stays_whole_in_the_mail() {
        let link = format!("http://127.0.0.1:8080/results/{}?view=private&token={}", "0".repeat(36), "a".repeat(43));
        let mail = formatted(&format!("Your results:\n\n{link}\n"));
        assert!(mail.contains("Content-Transfer-Encoding: 7bit"), "{mail}");
        assert!(mail.contains(&format!("\r\n{link}\r\n")), "the link is cut or encoded:\n{mail}");
    }

    #[test]
    fn text_that_7_bit_cannot_carry_is_encoded() {
        for text in ["caf\u{e9} \u{b7} r\u{e9}sultats\n".to_string(), format!("{}\n", "x".repeat(999))] {
            let mail = formatted(&text);
            assert!(!mail.contains("Content-Transfer-Encoding: 7bit"), "{mail}");
            assert!(mail.is_ascii(), "{mail}");
        }
    }
}
