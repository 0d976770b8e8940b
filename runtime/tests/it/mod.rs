mod opencv;
mod tracker;
