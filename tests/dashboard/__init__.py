"""The web dashboard (issue 40): its page in a real browser, and how it listens."""
