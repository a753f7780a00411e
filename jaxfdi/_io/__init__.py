"""Input and output: results files written completely or not at all (``files``) and
progress displays (``progress``). Private: users reach them through the names ``jaxfdi``
exports."""
