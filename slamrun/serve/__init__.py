"""`slamrun serve`: a live, read-only web page of one campaign or of a folder of campaigns.

folders (which campaigns a folder holds, and the one guard every served file passes), snapshot (a campaign's
state as the page shows it, read from its ledger as `slamrun status` reads it), runview (one run's path over its
ground truth), app (the aiohttp server: routes, server-sent events, token and Host checks), static/ (the page's
own script and style, served by slamrun: no CDN)."""
