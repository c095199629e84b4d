"""PNG figures (matplotlib, Agg backend): what a person would rather look at than read."""
