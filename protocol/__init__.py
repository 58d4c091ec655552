"""The JSON Schemas of swarmpose's messages (shipped as ``swarmpose.protocol``); see README.md."""
