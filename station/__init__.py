"""The operator station: a web page to start, watch, stop and sign off campaigns.

The web server only reads the database and starts `gyrostand campaign run|resume|retry` and
`gyrostand report` as processes of their own: the database stays the source of truth, so a
browser closing or the server restarting loses nothing."""
